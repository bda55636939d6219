//! Integration tests for `clevrtex verify` on a dataset made by the real `clevrtex generate`
//! in two shards (two output folders, each with its manifest): their union verifies, and each
//! kind of damage is found and named.

use std::path::{Path, PathBuf};
use std::process::Output;
use std::sync::OnceLock;

use clevrtex_render::post::{self, PngKind};
use serde_json::Value;

use crate::util::{blender_or_skip, clevrtex, text};

/// Two shard folders of the same 4-image run (`--shard 0/2` and `1/2`), made once.
fn shards() -> Option<&'static (tempfile::TempDir, PathBuf, PathBuf)> {
    static S: OnceLock<Option<(tempfile::TempDir, PathBuf, PathBuf)>> = OnceLock::new();
    S.get_or_init(|| {
        let blender = blender_or_skip("verify tests")?;
        let dir = tempfile::tempdir().unwrap();
        let mut outs = Vec::new();
        for k in 0..2 {
            let out = dir.path().join(format!("shard{k}"));
            let o = clevrtex()
                .args(["generate", "--variant", "clevr", "-n", "4", "--seed", "3"])
                .args(["--width", "48", "--height", "36", "--samples", "1"])
                .args(["--passes", "rgb,mask,depth", "--workers", "1"])
                .args(["--shard", &format!("{k}/2"), "--blender"])
                .arg(&blender)
                .arg("--out")
                .arg(&out)
                .env_remove("SLURM_ARRAY_TASK_ID")
                .env_remove("JOB_COMPLETION_INDEX")
                .output()
                .unwrap();
            assert_eq!(o.status.code(), Some(0), "{}", text(&o));
            outs.push(out);
        }
        let b = outs.pop().unwrap();
        let a = outs.pop().unwrap();
        Some((dir, a, b))
    })
    .as_ref()
}

/// A fresh copy of both shard folders to damage.
fn copy() -> Option<(tempfile::TempDir, PathBuf, PathBuf)> {
    let (_, a, b) = shards()?;
    let dir = tempfile::tempdir().unwrap();
    let (ca, cb) = (dir.path().join("a"), dir.path().join("b"));
    for (from, to) in [(a, &ca), (b, &cb)] {
        let st = std::process::Command::new("cp")
            .arg("-a")
            .arg(from)
            .arg(to)
            .status()
            .unwrap();
        assert!(st.success());
    }
    Some((dir, ca, cb))
}

fn verify(dirs: &[&Path]) -> (Output, String) {
    let out = clevrtex().arg("verify").args(dirs).output().unwrap();
    let t = text(&out);
    (out, t)
}

fn sample(dir: &Path, index: u64, suffix: &str) -> PathBuf {
    dir.join(format!(
        "clevrtex_clevr/0/CLEVRTEX_clevr_{index:06}{suffix}"
    ))
}

#[test]
fn verify_passes_the_union_of_shards_and_finds_a_missing_shard() {
    let Some((_dir, a, b)) = copy() else { return };
    let (out, t) = verify(&[&a, &b]);
    assert_eq!(out.status.code(), Some(0), "{t}");
    assert!(
        t.contains("clevr: 4 of 4 expected samples whole (2 manifest(s)"),
        "{t}"
    );
    // One shard alone is not the whole run: its partner's indices are missing.
    let (out, t) = verify(&[&a]);
    assert_eq!(out.status.code(), Some(3), "{t}");
    assert!(t.contains("missing (2): 1, 3"), "{t}");
    assert!(t.contains("no manifest for shard(s) 1/2"), "{t}");
    assert!(
        t.contains("--shard 0/2"),
        "the repair names the run's command: {t}"
    );
}

#[test]
fn verify_finds_a_missing_sample() {
    let Some((_dir, a, b)) = copy() else { return };
    for s in [".png", "_flat.png", "_depth_0001.png", ".json"] {
        std::fs::remove_file(sample(&b, 3, s)).unwrap();
    }
    let (out, t) = verify(&[&a, &b]);
    assert_eq!(out.status.code(), Some(3), "{t}");
    assert!(t.contains("missing (1): 3"), "{t}");
}

#[test]
fn verify_finds_a_truncated_png() {
    let Some((_dir, a, b)) = copy() else { return };
    let f = sample(&a, 2, "_depth_0001.png");
    let bytes = std::fs::read(&f).unwrap();
    std::fs::write(&f, &bytes[..bytes.len() / 2]).unwrap();
    let (out, t) = verify(&[&a, &b]);
    assert_eq!(out.status.code(), Some(3), "{t}");
    assert!(
        t.contains("CLEVRTEX_clevr_000002_depth_0001.png`: cannot decode PNG"),
        "{t}"
    );
}

#[test]
fn verify_finds_a_mask_with_a_wrong_id() {
    let Some((_dir, a, b)) = copy() else { return };
    let f = sample(&a, 0, "_flat.png");
    let mask = post::decode_png(&f).unwrap();
    let n = {
        let meta: Value =
            serde_json::from_slice(&std::fs::read(sample(&a, 0, ".json")).unwrap()).unwrap();
        meta["num_objects"].as_u64().unwrap()
    };
    let mut ids: Vec<u8> = mask.data.iter().map(|&v| v as u8).collect();
    ids[0] = n as u8 + 1;
    let png = post::encode_png(PngKind::Palette8, mask.width, mask.height, &ids, &[]).unwrap();
    std::fs::write(&f, png).unwrap();
    let (out, t) = verify(&[&a, &b]);
    assert_eq!(out.status.code(), Some(3), "{t}");
    assert!(
        t.contains(&format!(
            "mask has id {} but the metadata has {n} objects",
            n + 1
        )),
        "{t}"
    );
}

#[test]
fn verify_finds_an_index_duplicated_across_shards() {
    let Some((_dir, a, b)) = copy() else { return };
    for s in [".png", "_flat.png", "_depth_0001.png", ".json"] {
        std::fs::copy(sample(&a, 0, s), sample(&b, 0, s)).unwrap();
    }
    let (out, t) = verify(&[&a, &b]);
    assert_eq!(out.status.code(), Some(3), "{t}");
    assert!(t.contains("duplicated indices (1):"), "{t}");
    assert!(t.contains("    0 in `"), "{t}");
}

#[test]
fn verify_finds_a_stray_temp_file_and_repairs() {
    let Some((_dir, a, b)) = copy() else { return };
    let tmp = sample(&a, 2, ".png.clevrtex-tmp");
    std::fs::write(&tmp, b"half").unwrap();
    let (out, t) = verify(&[&a, &b]);
    assert_eq!(out.status.code(), Some(3), "{t}");
    assert!(t.contains("temporary files left by killed runs (1)"), "{t}");
    let out = clevrtex()
        .args(["verify", "--remove-broken"])
        .args([&a, &b])
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(3), "{}", text(&out));
    assert!(!tmp.exists());
    let (out, t) = verify(&[&a, &b]);
    assert_eq!(out.status.code(), Some(0), "{t}");
}

#[test]
fn verify_finds_a_byte_change_against_the_manifest() {
    let Some((_dir, a, b)) = copy() else { return };
    // A change that keeps the metadata valid JSON with the same keys and values.
    let f = sample(&b, 1, ".json");
    let mut text_ = std::fs::read_to_string(&f).unwrap();
    text_.push('\n');
    std::fs::write(&f, text_).unwrap();
    let (out, t) = verify(&[&a, &b]);
    assert_eq!(out.status.code(), Some(3), "{t}");
    assert!(
        t.contains("`CLEVRTEX_clevr_000001.json` differs from the manifest"),
        "{t}"
    );
}
