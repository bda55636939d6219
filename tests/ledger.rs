//! The failure ledger (`failures.jsonl`): one entry per image, truncated lines dropped, an
//! unwritable ledger said so, retried failures leave it, concurrent shards share it.

use crate::generate::{fake_blender, generate_fake, generate_tiny_rgb_mask, ledger_lines};
use crate::util::{blender_or_skip, clevrtex, text};

/// The ledger keeps one entry per image however often it fails, drops a truncated line (from a
/// run killed mid-write) with a warning, and keeps other images' entries.
#[test]
fn ledger_has_one_entry_per_image_and_drops_truncated_lines() {
    let dir = tempfile::tempdir().unwrap();
    let ledger = dir.path().join("clevrtex_clevr/failures.jsonl");
    std::fs::create_dir_all(ledger.parent().unwrap()).unwrap();
    let other =
        r#"{"index":7,"stem":"CLEVRTEX_clevr_000007","variant":"clevr","error":"x","time_unix":0}"#;
    std::fs::write(
        &ledger,
        format!("{other}\n{{\"index\":0,\"stem\":\"CLEVRTE"),
    )
    .unwrap();
    for run in 0..2 {
        let out = generate_fake("crash", dir.path(), &["-n", "1", "--retries", "0"]);
        let t = text(&out);
        assert_eq!(out.status.code(), Some(3), "{t}");
        assert_eq!(
            t.contains("dropped 1 unreadable line(s) of the failure ledger"),
            run == 0,
            "run {run}: {t}"
        );
    }
    let lines = ledger_lines(dir.path());
    let stems: Vec<&str> = lines.iter().map(|l| l["stem"].as_str().unwrap()).collect();
    assert_eq!(
        stems,
        ["CLEVRTEX_clevr_000000", "CLEVRTEX_clevr_000007"],
        "{lines:?}"
    );
}

/// A ledger that cannot be written (here: its lock file's name is taken by a folder, as a full
/// disk would fail the write) stops the run with a message that says the failure was NOT
/// recorded, and leaves the ledger on disk as it was (no 0-byte file).
#[test]
fn unwritable_ledger_says_so_and_keeps_the_old_one() {
    let dir = tempfile::tempdir().unwrap();
    let ledger = dir.path().join("clevrtex_clevr/failures.jsonl");
    std::fs::create_dir_all(ledger.parent().unwrap()).unwrap();
    let old =
        r#"{"index":7,"stem":"CLEVRTEX_clevr_000007","variant":"clevr","error":"x","time_unix":0}"#;
    std::fs::write(&ledger, format!("{old}\n")).unwrap();
    // The ledger's lock file taken by a folder: the ledger cannot be written.
    std::fs::create_dir_all(dir.path().join("clevrtex_clevr/.failures.jsonl.lock")).unwrap();
    let out = generate_fake("crash", dir.path(), &["-n", "1", "--retries", "0"]);
    let t = text(&out);
    assert_eq!(out.status.code(), Some(1), "{t}");
    assert!(!t.contains("recorded in `"), "{t}");
    assert!(
        t.contains("image 0 failed and its failure could not be recorded in the ledger"),
        "{t}"
    );
    assert_eq!(
        std::fs::read_to_string(&ledger).unwrap(),
        format!("{old}\n")
    );
}

#[test]
fn a_retried_failure_leaves_the_ledger() {
    let Some(blender) = blender_or_skip("a_retried_failure_leaves_the_ledger") else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let ledger = dir.path().join("clevrtex_clevr/failures.jsonl");
    std::fs::create_dir_all(ledger.parent().unwrap()).unwrap();
    // An earlier run failed on images 0 and 5; this one redoes image 0 only.
    let line = |i: u64| {
        format!(
            "{{\"index\":{i},\"stem\":\"CLEVRTEX_clevr_{i:06}\",\"variant\":\"clevr\",\"error\":\"x\",\"time_unix\":0}}\n"
        )
    };
    std::fs::write(&ledger, line(0) + &line(5)).unwrap();
    let run = || generate_tiny_rgb_mask(&blender, dir.path());
    let out = run();
    assert_eq!(out.status.code(), Some(0), "{}", text(&out));
    let left = ledger_lines(dir.path());
    assert_eq!(left.len(), 1, "{left:?}");
    assert_eq!(left[0]["index"], 5);
    // Once nothing is missing, the ledger goes.
    std::fs::write(&ledger, line(0)).unwrap();
    let out = run();
    assert_eq!(out.status.code(), Some(0), "{}", text(&out));
    assert!(
        !ledger.exists(),
        "the ledger of a complete run is still there"
    );
}

/// Shards writing into one folder at the same time (a SLURM array, a Kubernetes Indexed Job)
/// share the failure ledger: every shard's failures are kept, one entry per image.
#[test]
fn concurrent_shards_share_the_ledger_without_losing_entries() {
    let dir = tempfile::tempdir().unwrap();
    let spawn = |k: u32| {
        clevrtex()
            .env("FAKE_BLENDER_MODE", "crash")
            .env_remove("CLEVRTEX_BLENDER")
            .args([
                "generate",
                "--variant",
                "clevr",
                "-n",
                "8",
                "--retries",
                "0",
            ])
            .args([
                "--width",
                "64",
                "--height",
                "48",
                "--samples",
                "1",
                "--workers",
                "2",
            ])
            .args(["--shard", &format!("{k}/2"), "--blender"])
            .arg(fake_blender())
            .arg("--out")
            .arg(dir.path())
            .stdout(std::process::Stdio::null())
            .stderr(std::process::Stdio::null())
            .spawn()
            .unwrap()
    };
    let (mut a, mut b) = (spawn(0), spawn(1));
    assert_eq!(a.wait().unwrap().code(), Some(3));
    assert_eq!(b.wait().unwrap().code(), Some(3));
    let mut indices: Vec<u64> = ledger_lines(dir.path())
        .iter()
        .map(|l| l["index"].as_u64().unwrap())
        .collect();
    indices.sort();
    assert_eq!(indices, (0..8).collect::<Vec<u64>>());
}
