//! Stopping and going on: an interrupted or SIGTERM'd run leaves no partial sample and resumes,
//! a killed `clevrtex` leaves no worker or temporary folder, a rewritten sample keeps no old
//! pass files.

use std::path::Path;
use std::time::{Duration, Instant};

use crate::generate::{files_under, generate_tiny_rgb_mask};
use crate::util::{blender_or_skip, clevrtex, text};

#[test]
fn interrupted_run_leaves_no_partial_sample_and_resumes() {
    let Some(blender) = blender_or_skip("interrupted_run_leaves_no_partial_sample_and_resumes")
    else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let cmd = |n: &str| {
        let mut c = clevrtex();
        c.args(["generate", "--variant", "clevr", "-n", n])
            .args([
                "--width",
                "64",
                "--height",
                "48",
                "--samples",
                "1",
                "--workers",
                "1",
            ])
            .args(["--passes", "rgb,mask,depth"])
            // The resume below covers a part of the range (another --total).
            .arg("--allow-split-mismatch")
            .arg("--blender")
            .arg(&blender)
            .arg("--out")
            .arg(dir.path());
        c
    };
    let child = cmd("6")
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    let sub = dir.path().join("clevrtex_clevr/0");
    let first = sub.join("CLEVRTEX_clevr_000000.json");
    let deadline = Instant::now() + Duration::from_secs(120);
    while !first.exists() && Instant::now() < deadline {
        std::thread::sleep(Duration::from_millis(50));
    }
    assert!(first.exists(), "the first sample never appeared");
    let status = std::process::Command::new("kill")
        .args(["-INT", &child.id().to_string()])
        .status()
        .unwrap();
    assert!(status.success());
    let out = child.wait_with_output().unwrap();
    let t = text(&out);
    assert_eq!(out.status.code(), Some(130), "{t}");
    assert!(t.contains("hint: rerun the same command"), "{t}");
    // Every sample is either complete or absent; no temporary file is left.
    let files = files_under(dir.path());
    assert!(!files.iter().any(|f| f.contains("tmp")), "{files:?}");
    let done = (0..6)
        .filter(|i| sub.join(format!("CLEVRTEX_clevr_{i:06}.json")).exists())
        .count();
    for i in 0..6 {
        let parts = ["", "_flat", "_depth_0001"]
            .iter()
            .filter(|s| sub.join(format!("CLEVRTEX_clevr_{i:06}{s}.png")).exists())
            .count();
        let has_json = sub.join(format!("CLEVRTEX_clevr_{i:06}.json")).exists();
        assert!(
            (parts == 3 && has_json) || (parts == 0 && !has_json),
            "sample {i} is partial: {files:?}"
        );
    }
    assert!(
        done < 6,
        "the run was not interrupted early enough to test anything"
    );
    // Resume the first 3 images only (keeps the test short): finished ones are skipped.
    let out = cmd("3").output().unwrap();
    let t = text(&out);
    assert_eq!(out.status.code(), Some(0), "{t}");
    assert!(
        t.contains(&format!("({} already complete", done.min(3))),
        "resume skips finished samples\n{t}"
    );
    for i in 0..3 {
        assert!(sub.join(format!("CLEVRTEX_clevr_{i:06}.json")).exists());
    }
}

#[test]
fn a_rewritten_sample_keeps_no_pass_files_of_an_earlier_run() {
    let Some(blender) = blender_or_skip("a_rewritten_sample_keeps_no_pass_files_of_an_earlier_run")
    else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let sub = dir.path().join("clevrtex_clevr/0");
    std::fs::create_dir_all(&sub).unwrap();
    // An earlier run with all passes (e.g. another seed): its depth would not match the new
    // image.
    let stale = sub.join("CLEVRTEX_clevr_000000_depth_0001.png");
    std::fs::write(&stale, b"old").unwrap();
    let out = generate_tiny_rgb_mask(&blender, dir.path());
    let t = text(&out);
    assert_eq!(out.status.code(), Some(0), "{t}");
    assert!(sub.join("CLEVRTEX_clevr_000000.png").is_file(), "{t}");
    assert!(!stale.exists(), "the stale depth file is still there");
}

/// Processes whose command line mentions `dir`.
fn processes_mentioning(dir: &Path) -> Vec<String> {
    let o = std::process::Command::new("pgrep")
        .arg("-af")
        .arg(dir.display().to_string())
        .output()
        .unwrap();
    String::from_utf8_lossy(&o.stdout)
        .lines()
        .map(str::to_string)
        .collect()
}

/// `kill -9` of clevrtex mid-run: its Blender workers die with it (parent-death signal), and
/// the temporary folders it could not remove are removed by the next run.
#[test]
fn workers_and_temp_folders_do_not_outlive_a_killed_clevrtex() {
    let Some(blender) = blender_or_skip("workers_do_not_outlive_a_killed_clevrtex") else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let tmp = dir.path().join("tmp");
    std::fs::create_dir_all(&tmp).unwrap();
    let out = dir.path().join("out");
    // Renders long enough (thousands of samples) that a worker left alone would still be
    // busy well after the deadline below.
    let gen = |samples: &str| {
        let mut c = clevrtex();
        c.args([
            "generate",
            "--variant",
            "clevr",
            "-n",
            "2",
            "--workers",
            "2",
        ])
        .args(["--width", "64", "--height", "48", "--samples", samples])
        .arg("--blender")
        .arg(&blender)
        .arg("--out")
        .arg(&out)
        .env("TMPDIR", &tmp)
        .stdout(std::process::Stdio::null())
        .stderr(std::process::Stdio::null());
        c
    };
    let mut child = gen("20000").spawn().unwrap();
    let deadline = Instant::now() + Duration::from_secs(120);
    while processes_mentioning(&tmp).len() < 2 {
        assert!(Instant::now() < deadline, "no Blender worker started");
        std::thread::sleep(Duration::from_millis(100));
    }
    // Into the long final renders.
    std::thread::sleep(Duration::from_secs(4));
    child.kill().unwrap(); // SIGKILL
    child.wait().unwrap();
    // Dying takes Blender a moment, longer on a loaded machine (seen: over 3 s at load 8);
    // a worker left alone would render for minutes.
    let deadline = Instant::now() + Duration::from_secs(15);
    while !processes_mentioning(&tmp).is_empty() {
        assert!(
            Instant::now() < deadline,
            "workers outlived their killed parent: {:?}",
            processes_mentioning(&tmp)
        );
        std::thread::sleep(Duration::from_millis(100));
    }
    let ours = |tmp: &Path| -> Vec<String> {
        std::fs::read_dir(tmp)
            .unwrap()
            .flatten()
            .map(|e| e.file_name().to_string_lossy().into_owned())
            .filter(|n| n.starts_with("clevrtex-"))
            .collect()
    };
    assert!(
        !ours(&tmp).is_empty(),
        "a killed run cannot clean up after itself"
    );
    // The next run removes them, finishes, and leaves nothing behind itself.
    let o = gen("1")
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped())
        .arg("--overwrite")
        .output()
        .unwrap();
    assert_eq!(o.status.code(), Some(0), "{}", text(&o));
    assert_eq!(ours(&tmp), Vec::<String>::new());
    let blender_dirs: Vec<_> = std::fs::read_dir(&tmp)
        .unwrap()
        .flatten()
        .filter(|e| e.file_name().to_string_lossy().starts_with("blender"))
        .collect();
    assert!(
        blender_dirs.is_empty(),
        "Blender's own temporary folders are ours to remove"
    );
}

/// SIGTERM (what `timeout`, SLURM and Kubernetes send) mid-render: like Ctrl-C, the workers are
/// stopped, no partial sample or temporary file is left, and the exit code is 143.
#[test]
fn sigterm_stops_workers_and_leaves_no_partial_output() {
    let Some(blender) = blender_or_skip("sigterm_stops_workers") else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let tmp = dir.path().join("tmp");
    std::fs::create_dir_all(&tmp).unwrap();
    let out = dir.path().join("out");
    let child = clevrtex()
        .args([
            "generate",
            "--variant",
            "clevr",
            "-n",
            "4",
            "--workers",
            "2",
        ])
        .args(["--width", "64", "--height", "48", "--quality", "reference"])
        .args(["--samples", "20000", "--blender"])
        .arg(&blender)
        .arg("--out")
        .arg(&out)
        .env("TMPDIR", &tmp)
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    let deadline = Instant::now() + Duration::from_secs(120);
    while processes_mentioning(&tmp).len() < 2 {
        assert!(Instant::now() < deadline, "no Blender worker started");
        std::thread::sleep(Duration::from_millis(100));
    }
    std::thread::sleep(Duration::from_secs(4));
    let t = Instant::now();
    let st = std::process::Command::new("kill")
        .args(["-TERM", &child.id().to_string()])
        .status()
        .unwrap();
    assert!(st.success());
    let o = child.wait_with_output().unwrap();
    let t_ = text(&o);
    assert_eq!(o.status.code(), Some(143), "{t_}");
    assert!(t.elapsed() < Duration::from_secs(20), "{:?}", t.elapsed());
    assert!(t_.contains("terminate (SIGTERM)"), "{t_}");
    assert!(
        processes_mentioning(&tmp).is_empty(),
        "{:?}",
        processes_mentioning(&tmp)
    );
    let left: Vec<String> = files_under(dir.path())
        .into_iter()
        .filter(|f| f.contains("clevrtex-tmp") || f.starts_with("tmp/"))
        .collect();
    assert!(left.is_empty(), "left behind: {left:?}");
    // Whatever was finished is whole (here: nothing, at 20,000 samples per image).
    for f in files_under(&out).iter().filter(|f| f.ends_with(".json")) {
        let stem = f.rsplit('/').next().unwrap().trim_end_matches(".json");
        if stem.starts_with("CLEVRTEX_") {
            assert!(out.join(f.replace(".json", "_flat.png")).is_file(), "{f}");
        }
    }
}

/// Issue 42, finding 9: `generate -n 100000000` (the cap) made one folder per 1,000 indices and
/// checked every index's files before its first image, deaf to SIGTERM for 23 minutes. The
/// indices are now walked lazily, as workers take them: a folder is made when an image is
/// written, and SIGTERM stops the run at once (exit 143).
#[test]
fn a_run_at_the_index_cap_makes_no_folder_up_front_and_stops_on_sigterm() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("out");
    let mut c =
        crate::many_writers::generate(&crate::util::fake_blender(), &out, &["-n", "100000000"]);
    let child = c
        .env("FAKE_BLENDER_MODE", "hang")
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    let vdir = out.join("clevrtex_clevr");
    let lock = vdir.join(".clevrtex-run-0-100000000-0of1.lock");
    let t = Instant::now();
    while !lock.exists() && t.elapsed() < Duration::from_secs(60) {
        std::thread::sleep(Duration::from_millis(50));
    }
    assert!(lock.exists(), "the run never took its lock");
    std::thread::sleep(Duration::from_secs(2));
    let sent = Instant::now();
    let st = std::process::Command::new("kill")
        .args(["-TERM", &child.id().to_string()])
        .status()
        .unwrap();
    assert!(st.success());
    let pid = child.id();
    let waiter = std::thread::spawn(move || child.wait_with_output().unwrap());
    while !waiter.is_finished() && sent.elapsed() < Duration::from_secs(30) {
        std::thread::sleep(Duration::from_millis(50));
    }
    if !waiter.is_finished() {
        let _ = std::process::Command::new("kill")
            .args(["-KILL", &pid.to_string()])
            .status();
        panic!("SIGTERM did not stop the run within 30 s");
    }
    let o = waiter.join().unwrap();
    let t = text(&o);
    assert_eq!(o.status.code(), Some(143), "{t}");
    let folders: Vec<_> = std::fs::read_dir(&vdir)
        .unwrap()
        .flatten()
        .filter(|e| e.file_type().is_ok_and(|t| t.is_dir()))
        .map(|e| e.file_name())
        .collect();
    assert!(
        folders.is_empty(),
        "folders made before any image: {folders:?}"
    );
}

/// Issue 48: a rerun never blesses bytes it did not write. A metadata file changed after the
/// run (`verify` fails), then the run's own command again: the sample is not "already
/// complete" (with `--blender /bin/false` the run fails instead of passing, and its manifest
/// records no hash of the changed file); with Blender it is made again, byte-identical to
/// the first, and `verify` passes. The same with the manifest's hashes rewritten to match the
/// change (the sample's layout does not re-derive).
#[test]
fn a_rerun_remakes_a_changed_sample_instead_of_blessing_it() {
    let Some(blender) = blender_or_skip("a rerun remakes a changed sample") else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("data");
    let generate = |blender: &Path| {
        clevrtex()
            .args(["generate", "--variant", "clevr", "-n", "2", "--seed", "5"])
            .args(["--width", "32", "--height", "24", "--samples", "1"])
            .args(["--passes", "rgb,mask", "--workers", "1", "--blender"])
            .arg(blender)
            .arg("--out")
            .arg(&out)
            .env_remove("SLURM_ARRAY_TASK_ID")
            .env_remove("JOB_COMPLETION_INDEX")
            .output()
            .unwrap()
    };
    let verify = || {
        let o = clevrtex().arg("verify").arg(&out).output().unwrap();
        (o.status.code(), text(&o))
    };
    let o = generate(&blender);
    assert_eq!(o.status.code(), Some(0), "{}", text(&o));
    let meta = out.join("clevrtex_clevr/0/CLEVRTEX_clevr_000000.json");
    let manifest = out.join("clevrtex_clevr/MANIFEST-0-2-0of1.json");
    let original = std::fs::read(&meta).unwrap();
    for rehash in [false, true] {
        let mut m: serde_json::Value = serde_json::from_slice(&original).unwrap();
        m["ground_material"] = "forged".into();
        let forged = serde_json::to_vec_pretty(&m).unwrap();
        std::fs::write(&meta, &forged).unwrap();
        let forged_hash = clevrtex_dataset::manifest::hash_hex(&forged);
        if rehash {
            let mut man: serde_json::Value =
                serde_json::from_slice(&std::fs::read(&manifest).unwrap()).unwrap();
            man["files"]["0/CLEVRTEX_clevr_000000.json"]["xxh3"] = forged_hash.clone().into();
            man["files"]["0/CLEVRTEX_clevr_000000.json"]["size"] = forged.len().into();
            std::fs::write(&manifest, serde_json::to_vec_pretty(&man).unwrap()).unwrap();
        }
        let (code, t) = verify();
        assert_eq!(code, Some(3), "rehash {rehash}: {t}");

        let o = generate(Path::new("/bin/false"));
        let t = text(&o);
        assert_ne!(o.status.code(), Some(0), "rehash {rehash}: blessed: {t}");
        let man = std::fs::read_to_string(&manifest).unwrap();
        if !rehash {
            assert!(!man.contains(&forged_hash), "rehash {rehash}: {man}");
        }
        let (code, t) = verify();
        assert_eq!(code, Some(3), "rehash {rehash}: {t}");

        let o = generate(&blender);
        let t = text(&o);
        assert_eq!(o.status.code(), Some(0), "rehash {rehash}: {t}");
        assert!(
            t.contains("did not pass `clevrtex verify`'s check, so they were made again")
                && t.contains("CLEVRTEX_clevr_000000"),
            "rehash {rehash}: {t}"
        );
        assert_eq!(
            std::fs::read(&meta).unwrap(),
            original,
            "rehash {rehash}: made again, byte-identical"
        );
        let man = std::fs::read_to_string(&manifest).unwrap();
        assert!(!man.contains(&forged_hash), "rehash {rehash}: {man}");
        let (code, t) = verify();
        assert_eq!(code, Some(0), "rehash {rehash}: {t}");
    }
}
