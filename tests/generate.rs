//! Integration tests for `clevrtex generate`, `clevrtex render` and `clevrtex doctor`.
//!
//! Failure paths use the fake Blender of `tests/fake_blender/` (selected with `--blender`
//! and `FAKE_BLENDER_MODE`); real paths use the real Blender with tiny images, and skip
//! visibly without it (see `util::blender_or_skip`).

use std::path::{Path, PathBuf};
use std::process::Output;
use std::sync::atomic::AtomicBool;
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use clevrtex_render::pool::{self, Job, PoolEvent, PoolOptions, SampleStats};
use clevrtex_render::post::{self, decode_png};
use clevrtex_scene::{Pass, SceneFile};
use serde_json::Value;

use crate::util::{blender_or_skip, clevrtex, data, repo_root, test_blenders, text};

fn fake_blender() -> PathBuf {
    repo_root().join("tests/fake_blender/blender")
}

/// `clevrtex generate` of one tiny clevr image with the fake Blender in `mode`.
fn generate_fake(mode: &str, out: &Path, extra: &[&str]) -> Output {
    clevrtex()
        .env("FAKE_BLENDER_MODE", mode)
        .env_remove("CLEVRTEX_BLENDER")
        .args([
            "generate",
            "--variant",
            "clevr",
            "--width",
            "64",
            "--height",
            "48",
        ])
        .args(["--samples", "1", "--workers", "1", "--out"])
        .arg(out)
        .arg("--blender")
        .arg(fake_blender())
        .args(extra)
        .output()
        .expect("run clevrtex")
}

/// `clevrtex generate` of image 0 of `clevr` at 64x48, 1 sample, rgb and mask, with the real
/// Blender.
fn generate_tiny_rgb_mask(blender: &Path, out: &Path) -> Output {
    clevrtex()
        .args([
            "generate",
            "--variant",
            "clevr",
            "-n",
            "1",
            "--passes",
            "rgb,mask",
        ])
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
        .arg("--blender")
        .arg(blender)
        .arg("--out")
        .arg(out)
        .output()
        .expect("run clevrtex")
}

fn ledger_lines(out: &Path) -> Vec<Value> {
    let path = out.join("clevrtex_clevr/failures.jsonl");
    std::fs::read_to_string(&path)
        .unwrap_or_default()
        .lines()
        .map(|l| serde_json::from_str(l).expect("ledger lines are JSON"))
        .collect()
}

/// Every file under `dir`, relative, sorted.
fn files_under(dir: &Path) -> Vec<String> {
    fn walk(root: &Path, dir: &Path, out: &mut Vec<String>) {
        if let Ok(entries) = std::fs::read_dir(dir) {
            for e in entries.flatten() {
                let p = e.path();
                if p.is_dir() {
                    walk(root, &p, out);
                } else {
                    out.push(p.strip_prefix(root).unwrap().display().to_string());
                }
            }
        }
    }
    let mut v = Vec::new();
    walk(dir, dir, &mut v);
    v.sort();
    v
}

/// The Rust pass table (`clevrtex_scene::passes`) and the bridge's (`blender_scripts/passes.py`)
/// list the same passes, in the same order, with the same EXR layers: read in Blender's own
/// Python, the interpreter that runs the bridge.
#[test]
fn pass_table_rust_and_bridge_agree() {
    let Some(blender) = blender_or_skip("pass_table_rust_and_bridge_agree") else {
        return;
    };
    let scripts = repo_root().join("blender_scripts");
    let expr = format!(
        "import json, sys; sys.path.insert(0, {scripts:?}); import passes; \
         print('@@PASSES@@' + json.dumps([[n, list(p['exr'].items())] for n, p in passes.PASSES.items()]))",
        scripts = scripts.display().to_string()
    );
    // A Python with the `bpy` module (`CLEVRTEX_BLENDER=.venv-bpy/bin/python`) runs the
    // bridge itself, so it reads the table there, without Blender's command line.
    let args: Vec<&str> = match clevrtex_render::blender::flavour(&blender) {
        clevrtex_render::blender::Flavour::PythonModule => vec!["-c", &expr],
        clevrtex_render::blender::Flavour::Executable => vec![
            "-b",
            "--factory-startup",
            "--python-exit-code",
            "1",
            "--python-expr",
            &expr,
        ],
    };
    let out = std::process::Command::new(&blender)
        .args(&args)
        .output()
        .unwrap();
    let stdout = String::from_utf8_lossy(&out.stdout);
    let line = stdout
        .lines()
        .find_map(|l| l.strip_prefix("@@PASSES@@"))
        .unwrap_or_else(|| panic!("no pass table printed: {stdout}\n{}", text(&out)));
    let bridge: Vec<(String, Vec<(String, String)>)> = serde_json::from_str(line).unwrap();
    let rust: Vec<(String, Vec<(String, String)>)> = Pass::ALL
        .iter()
        .map(|p| {
            let layers = p.spec().exr_layers.iter();
            let layers = layers
                .map(|(l, c)| (l.to_string(), c.to_string()))
                .collect();
            (p.name().to_string(), layers)
        })
        .collect();
    assert_eq!(
        bridge, rust,
        "blender_scripts/passes.py PASSES vs clevrtex_scene::passes (names and EXR layers)"
    );
}

#[test]
fn missing_blender_is_named_with_the_install_hint() {
    let dir = tempfile::tempdir().unwrap();
    let out = clevrtex()
        .args([
            "generate",
            "--variant",
            "clevr",
            "-n",
            "1",
            "--blender",
            "/no/such/blender",
            "--out",
        ])
        .arg(dir.path())
        .output()
        .unwrap();
    let t = text(&out);
    assert_eq!(out.status.code(), Some(1), "{t}");
    assert!(t.contains("`/no/such/blender`"), "{t}");
    assert!(t.contains("apt-get install blender"), "{t}");
    assert!(t.contains("--blender"), "{t}");
}

#[test]
fn fake_crash_is_retried_then_recorded_in_the_ledger() {
    let dir = tempfile::tempdir().unwrap();
    let out = generate_fake("crash", dir.path(), &["-n", "1", "--retries", "1"]);
    let t = text(&out);
    assert_eq!(out.status.code(), Some(3), "partial exit code\n{t}");
    // The report names the program, the exit status and the stderr tail.
    assert!(t.contains("restarting a Blender worker"), "{t}");
    assert!(t.contains("SIGSEGV"), "{t}");
    assert!(t.contains("--- stderr"), "{t}");
    assert!(t.contains("segmentation fault while rendering"), "{t}");
    let ledger = ledger_lines(dir.path());
    assert_eq!(ledger.len(), 1, "{ledger:?}");
    assert_eq!(ledger[0]["index"], 0);
    assert_eq!(ledger[0]["stem"], "CLEVRTEX_clevr_000000");
    assert!(
        !files_under(dir.path()).iter().any(|f| f.ends_with(".png")),
        "no image of a failed sample: {:?}",
        files_under(dir.path())
    );
}

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
fn render_finds_the_scene_files_of_a_sample_output_folder() {
    // `clevrtex sample --out scenes` nests its files as `clevrtex_<variant>/<k>/`; `clevrtex
    // render scenes` must find them (the fake crashes, so each found scene is in the ledger).
    let dir = tempfile::tempdir().unwrap();
    let scenes = dir.path().join("scenes");
    let out = clevrtex()
        .args(["sample", "--variant", "clevr", "-n", "2", "--out"])
        .arg(&scenes)
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(0), "{}", text(&out));
    let data = dir.path().join("data");
    let out = clevrtex()
        .env("FAKE_BLENDER_MODE", "crash")
        .env_remove("CLEVRTEX_BLENDER")
        .args(["render", "--workers", "1", "--retries", "0", "--blender"])
        .arg(fake_blender())
        .arg("--out")
        .arg(&data)
        .arg(&scenes)
        .output()
        .unwrap();
    let t = text(&out);
    assert_eq!(out.status.code(), Some(3), "{t}");
    let ledger = ledger_lines(&data);
    let indices: Vec<u64> = ledger
        .iter()
        .map(|l| l["index"].as_u64().unwrap())
        .collect();
    assert_eq!(indices.len(), 2, "{ledger:?}");
    assert!(indices.contains(&0) && indices.contains(&1), "{ledger:?}");
}

#[test]
fn render_into_the_scene_folder_keeps_the_scene_files() {
    let dir = tempfile::tempdir().unwrap();
    let out = clevrtex()
        .args(["sample", "--variant", "clevr", "-n", "1", "--out"])
        .arg(dir.path())
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(0), "{}", text(&out));
    let scene = dir
        .path()
        .join("clevrtex_clevr/0/CLEVRTEX_clevr_000000.json");
    let before = std::fs::read(&scene).unwrap();
    let out = clevrtex()
        .env("FAKE_BLENDER_MODE", "crash")
        .env_remove("CLEVRTEX_BLENDER")
        .args(["render", "--retries", "0", "--blender"])
        .arg(fake_blender())
        .arg("--out")
        .arg(dir.path())
        .arg(dir.path())
        .output()
        .unwrap();
    let t = text(&out);
    assert_eq!(out.status.code(), Some(1), "{t}");
    assert!(
        t.contains("CLEVRTEX_clevr_000000.json`") && t.contains("--out"),
        "{t}"
    );
    assert_hint_is_last(&t);
    assert_eq!(
        std::fs::read(&scene).unwrap(),
        before,
        "the scene file changed"
    );
}

#[test]
fn doctor_names_a_broken_blender_with_its_stderr_tail() {
    let out = clevrtex()
        .env("FAKE_BLENDER_MODE", "noready")
        .env_remove("CLEVRTEX_BLENDER")
        .args(["doctor", "--blender"])
        .arg(fake_blender())
        .output()
        .unwrap();
    let t = text(&out);
    assert_eq!(out.status.code(), Some(1), "{t}");
    assert!(t.contains("No module named 'bpy'"), "{t}");
    assert!(
        !t.contains("run `clevrtex doctor`"),
        "doctor points to itself: {t}"
    );
    assert!(t.contains("apt-get install blender"), "{t}");
}

#[test]
fn render_of_an_empty_folder_names_it() {
    let dir = tempfile::tempdir().unwrap();
    let out = clevrtex()
        .args(["render", "--out"])
        .arg(dir.path().join("data"))
        .arg(dir.path())
        .output()
        .unwrap();
    let t = text(&out);
    assert_eq!(out.status.code(), Some(1), "{t}");
    assert!(
        t.contains(&format!("`{}`", dir.path().display())) && t.contains("hint:"),
        "{t}"
    );
}

#[test]
fn fake_hang_times_out_and_is_killed() {
    let dir = tempfile::tempdir().unwrap();
    let t0 = Instant::now();
    let out = generate_fake(
        "hang",
        dir.path(),
        &["-n", "1", "--retries", "0", "--timeout", "1.5"],
    );
    let t = text(&out);
    assert_eq!(out.status.code(), Some(3), "{t}");
    assert!(t.contains("timed out after 1.5 s"), "{t}");
    assert!(
        t.contains("CLEVRTEX_clevr_000000"),
        "the report names the scene\n{t}"
    );
    assert!(
        t0.elapsed() < Duration::from_secs(30),
        "took {:?}",
        t0.elapsed()
    );
    assert_eq!(ledger_lines(dir.path()).len(), 1);
}

#[test]
fn fake_garbage_is_a_protocol_error() {
    let dir = tempfile::tempdir().unwrap();
    let out = generate_fake("garbage", dir.path(), &["-n", "1", "--retries", "0"]);
    let t = text(&out);
    assert_eq!(out.status.code(), Some(3), "{t}");
    assert!(t.contains("malformed reply"), "{t}");
    assert!(t.contains("this is not json"), "{t}");
    // Says what happened, not that the install is broken.
    assert!(t.contains("a reply line was cut or garbled"), "{t}");
    assert!(!t.contains("disagree") && !t.contains("reinstall"), "{t}");
}

#[test]
fn fake_chatter_then_exit_is_a_crash_not_a_reply() {
    let dir = tempfile::tempdir().unwrap();
    let out = generate_fake("chatter", dir.path(), &["-n", "1", "--retries", "0"]);
    let t = text(&out);
    assert_eq!(out.status.code(), Some(3), "{t}");
    assert!(t.contains("exited (exit status: 0)"), "{t}");
    assert!(
        t.contains("--- stdout (last 25 lines)"),
        "chatter is kept as a tail\n{t}"
    );
}

#[test]
fn fake_crash_with_fail_fast_stops_the_run() {
    let dir = tempfile::tempdir().unwrap();
    let out = generate_fake(
        "crash",
        dir.path(),
        &["-n", "3", "--retries", "0", "--fail-fast"],
    );
    let t = text(&out);
    assert_eq!(out.status.code(), Some(1), "{t}");
    assert_eq!(
        ledger_lines(dir.path()).len(),
        1,
        "stopped after the first failure\n{t}"
    );
}

#[test]
fn broken_blender_stops_the_run_with_its_stderr_tail() {
    let dir = tempfile::tempdir().unwrap();
    let out = generate_fake("noready", dir.path(), &["-n", "2"]);
    let t = text(&out);
    assert_eq!(out.status.code(), Some(1), "{t}");
    assert!(t.contains("No module named 'bpy'"), "{t}");
    assert!(
        ledger_lines(dir.path()).is_empty(),
        "a broken install is not a per-image failure"
    );
}

#[test]
fn unwritable_output_is_named() {
    let dir = tempfile::tempdir().unwrap();
    let file = dir.path().join("not-a-folder");
    std::fs::write(&file, b"x").unwrap();
    let out = generate_fake("crash", &file, &["-n", "1"]);
    let t = text(&out);
    assert_eq!(out.status.code(), Some(1), "{t}");
    assert!(t.contains("not-a-folder`"), "{t}");
    assert_hint_is_last(&t);
}

/// The `hint:` line ends the message: the OS error comes before it, once.
fn assert_hint_is_last(t: &str) {
    let last = t.trim_end().lines().last().unwrap_or_default();
    assert!(
        last.starts_with("hint:"),
        "the hint is not the last line:\n{t}"
    );
    assert!(
        !last.contains("os error"),
        "the cause is printed after the hint:\n{t}"
    );
    assert!(
        t.matches("os error").count() <= 1,
        "the cause is printed twice:\n{t}"
    );
}

#[test]
fn missing_config_is_named_with_its_cause_before_the_hint() {
    let dir = tempfile::tempdir().unwrap();
    let out = clevrtex()
        .args(["generate", "-n", "1", "--config"])
        .arg(dir.path().join("nope.json"))
        .arg("--out")
        .arg(dir.path())
        .output()
        .unwrap();
    let t = text(&out);
    assert_eq!(out.status.code(), Some(1), "{t}");
    assert!(t.contains("nope.json`") && t.contains("os error 2"), "{t}");
    assert_hint_is_last(&t);
}

#[test]
fn bad_passes_and_shards_are_usage_errors_with_hints() {
    let dir = tempfile::tempdir().unwrap();
    for (args, needle) in [
        (vec!["--passes", "rgb,sparkle"], "unknown pass `sparkle`"),
        (vec!["--shard", "4/4"], "invalid shard `4/4` from `--shard`"),
        (vec!["--shadow-samples", "0"], "--shadow-samples"),
        (vec!["--shadow-samples", "70000"], "--shadow-samples 70000"),
    ] {
        let out = generate_fake(
            "crash",
            dir.path(),
            &[&["-n", "1"], args.as_slice()].concat(),
        );
        let t = text(&out);
        assert_eq!(out.status.code(), Some(1), "{t}");
        assert!(t.contains(needle) && t.contains("hint:"), "{t}");
    }
}

// ---- real Blender -------------------------------------------------------------------------

fn read_json(path: &Path) -> Value {
    serde_json::from_str(&std::fs::read_to_string(path).unwrap()).unwrap()
}

/// The mask's ids are all in 0..=N and every object has more than the threshold's pixels.
fn check_mask(dir: &Path, stem: &str) -> Value {
    let meta = read_json(&dir.join(format!("{stem}.json")));
    let n = meta["num_objects"].as_u64().unwrap() as u16;
    let mask = decode_png(&dir.join(format!("{stem}_flat.png"))).unwrap();
    assert!(
        mask.palette && mask.bits == 8,
        "mask is an 8-bit palette PNG"
    );
    assert!(mask.data.iter().all(|&v| v <= n), "ids in 0..={n}");
    let threshold = meta["visibility_threshold_px"].as_u64().unwrap();
    for i in 1..=n {
        let count = mask.data.iter().filter(|&&v| v == i).count() as u64;
        assert!(
            count > threshold,
            "object {i} has {count} px <= {threshold}"
        );
        assert_eq!(meta["objects"][(i - 1) as usize]["visible_pixels"], count);
    }
    meta
}

#[test]
fn generate_writes_every_pass_with_exact_masks_and_resumes() {
    // On every Blender found: Debian's, and PyPI's bpy when installed.
    for blender in test_blenders("generate_writes_every_pass_with_exact_masks_and_resumes") {
        let dir = tempfile::tempdir().unwrap();
        let run = |extra: &[&str]| {
            clevrtex()
                .args(["generate", "--variant", "camo", "-n", "2", "--seed", "3"])
                .args([
                    "--width",
                    "80",
                    "--height",
                    "60",
                    "--samples",
                    "2",
                    "--workers",
                    "1",
                ])
                .arg("--blender")
                .arg(&blender)
                .arg("--out")
                .arg(dir.path())
                .args(extra)
                .output()
                .unwrap()
        };
        let out = run(&[]);
        let t = text(&out);
        assert_eq!(out.status.code(), Some(0), "{t}");
        assert!(t.contains("time split"), "{t}");
        let sub = dir.path().join("clevrtex_camo/0");
        let mut expected = Vec::new();
        for i in 0..2 {
            let stem = format!("CLEVRTEX_camo_{i:06}");
            for suffix in [
                ".json",
                ".png",
                "_albedo_0001.png",
                "_depth_0001.png",
                "_flat.png",
                "_normal_0001.png",
                "_shadow_0001.png",
            ] {
                expected.push(format!("clevrtex_camo/0/{stem}{suffix}"));
            }
            let meta = check_mask(&sub, &stem);
            for key in [
                "num_objects",
                "split",
                "image_index",
                "image_filename",
                "ground_material",
                "directions",
                "objects",
                "relationships",
                "mask_filename",
                "normal_filename",
                "albedo_filename",
                "depth_filename",
                "shadow_filename",
                "seed",
                "attempt",
                "camera",
                "passes",
                "render",
                "blender_version",
                "clevrtex_version",
            ] {
                assert!(meta.get(key).is_some(), "metadata lacks `{key}`");
            }
            assert_eq!(meta["image_filename"], format!("{stem}.png"));
            assert_eq!(meta["seed"], 3);
            assert_eq!(meta["render"]["width"], 80);
            let depth = decode_png(&sub.join(format!("{stem}_depth_0001.png"))).unwrap();
            assert_eq!(
                (depth.bits, depth.channels, depth.width, depth.height),
                (16, 1, 80, 60)
            );
            let normal = decode_png(&sub.join(format!("{stem}_normal_0001.png"))).unwrap();
            assert_eq!((normal.bits, normal.channels), (16, 3));
            let rgb = decode_png(&sub.join(format!("{stem}.png"))).unwrap();
            assert_eq!((rgb.bits, rgb.width, rgb.height), (8, 80, 60));
        }
        // The run's manifest (sizes and hashes of these files, for `clevrtex verify`).
        expected.push("clevrtex_camo/MANIFEST-0-2-0of1.json".to_string());
        // The guard of the run locks (an empty file that stays).
        expected.push("clevrtex_camo/.clevrtex-runs.lock".to_string());
        expected.sort();
        assert_eq!(files_under(dir.path()), expected);

        // Rerun: everything is complete, nothing is rendered again.
        let out = run(&[]);
        let t = text(&out);
        assert_eq!(out.status.code(), Some(0), "{t}");
        assert!(t.contains("rendered 0 images (2 already complete"), "{t}");

        // A sample with a missing file is incomplete and is redone; the other is kept.
        let keep = sub.join("CLEVRTEX_camo_000000.json");
        let before = std::fs::metadata(&keep).unwrap().modified().unwrap();
        std::fs::remove_file(sub.join("CLEVRTEX_camo_000001_shadow_0001.png")).unwrap();
        let out = run(&[]);
        let t = text(&out);
        assert!(t.contains("rendered 1 images (1 already complete"), "{t}");
        assert_eq!(
            std::fs::metadata(&keep).unwrap().modified().unwrap(),
            before
        );
        assert_eq!(files_under(dir.path()), expected);
    }
}

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
fn every_variant_renders_and_only_requested_passes_are_written() {
    // On every Blender found: Debian's, and PyPI's bpy when installed.
    for blender in test_blenders("every_variant_renders_and_only_requested_passes_are_written") {
        let dir = tempfile::tempdir().unwrap();
        let scenes = dir.path().join("scenes");
        std::fs::create_dir_all(&scenes).unwrap();
        let variants = ["full", "pbg", "vbg", "grassbg", "camo", "outd", "clevr"];
        for (i, v) in variants.iter().enumerate() {
            let config = clevrtex_scene::Config::builtin(v).unwrap();
            let mut scene = clevrtex_scene::sample(
                &config,
                &clevrtex_scene::SampleRequest {
                    seed: 1,
                    index: i as u64,
                    attempt: 0,
                    total: 10,
                },
            )
            .unwrap();
            scene.render.width = 64;
            scene.render.height = 48;
            scene.render.samples = 1;
            std::fs::write(
                scenes.join(format!("{v}.json")),
                serde_json::to_string(&scene).unwrap(),
            )
            .unwrap();
        }
        let out_dir = dir.path().join("out");
        let out = clevrtex()
            .args([
                "render",
                "--passes",
                "rgb,mask",
                "--workers",
                "1",
                "--blender",
            ])
            .arg(&blender)
            .arg("--out")
            .arg(&out_dir)
            .arg(&scenes)
            .output()
            .unwrap();
        let t = text(&out);
        assert_eq!(out.status.code(), Some(0), "{t}");
        let files = files_under(&out_dir);
        assert_eq!(files.len(), 3 * variants.len(), "{files:?}");
        for (i, v) in variants.iter().enumerate() {
            let stem = format!("clevrtex_{v}/0/CLEVRTEX_{v}_{i:06}");
            for suffix in [".json", ".png", "_flat.png"] {
                assert!(
                    files.contains(&format!("{stem}{suffix}")),
                    "{stem}{suffix}: {files:?}"
                );
            }
            let meta = read_json(&out_dir.join(format!("{stem}.json")));
            assert_eq!(meta["depth_filename"], Value::Null);
            assert_eq!(meta["passes"].as_object().unwrap().len(), 2);
            let mask = decode_png(&out_dir.join(format!("{stem}_flat.png"))).unwrap();
            let n = meta["num_objects"].as_u64().unwrap() as u16;
            assert!(mask.data.iter().all(|&v| v <= n));
            let rgb = decode_png(&out_dir.join(format!("{stem}.png"))).unwrap();
            let spread = rgb.data.iter().max().unwrap() - rgb.data.iter().min().unwrap();
            assert!(spread > 20, "{v}: the image is flat (spread {spread})");
        }
    }
}

fn fixture(name: &str, width: u32, height: u32, samples: u32) -> SceneFile {
    let text = std::fs::read_to_string(data(&format!("scenes/{name}.json"))).unwrap();
    let mut scene: SceneFile = serde_json::from_str(&text).unwrap();
    scene.render.width = width;
    scene.render.height = height;
    scene.render.samples = samples;
    scene
}

/// Render fixture scenes through the library pool (one worker), returning the stats.
fn render_fixtures(blender: PathBuf, out: &Path, scenes: Vec<SceneFile>) -> Vec<SampleStats> {
    let jobs = scenes
        .into_iter()
        .map(|s| {
            let s = Arc::new(s);
            Job {
                index: s.index,
                variant: s.variant.clone(),
                stem: s.stem.clone(),
                passes: Pass::ALL.to_vec(),
                scene: {
                    let s = Arc::clone(&s);
                    Arc::new(move |_| Ok((*s).clone()))
                },
                resample: false,
                source: None,
            }
        })
        .collect();
    let opts = PoolOptions {
        blender,
        materials_json: clevrtex_render::default_materials_json().unwrap(),
        workers: 1,
        threads: 0,
        timeout: None,
        startup_timeout: clevrtex_render::STARTUP_TIMEOUT,
        retries: 0,
        max_attempts: 1,
        visibility_check: true,
        keep_exr: true,
        overwrite: true,
        fail_fast: true,
        out: out.to_path_buf(),
        ledger: out.join("failures.jsonl"),
        interrupt: Arc::new(AtomicBool::new(false)),
        devices: Vec::new(),
    };
    let stats = Mutex::new(Vec::new());
    let report = pool::run(&opts, jobs, &|ev| {
        if let PoolEvent::Done { sample } = ev {
            stats.lock().unwrap().push((*sample).clone());
        }
    })
    .unwrap_or_else(|e| panic!("{e}"));
    assert!(report.failed.is_empty());
    let mut stats = stats.into_inner().unwrap();
    stats.sort_by_key(|s| s.index);
    stats
}

#[test]
fn camera_model_depth_and_shadow_match_blender() {
    let Some(blender) = blender_or_skip("camera_model_depth_and_shadow_match_blender") else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let (w, h) = (160, 120);
    let objects = fixture("tiny3", w, h, 4);
    let floor = fixture("empty_floor", 64, 48, 8);
    let stats = render_fixtures(blender, dir.path(), vec![objects.clone(), floor.clone()]);
    assert_eq!(stats.len(), 2);
    let sub = dir.path().join("clevrtex_clevr/0");

    // pixel_coords (Rust camera model) within 0.5 px of Blender's own projection.
    let meta = read_json(&sub.join(format!("{}.json", objects.stem)));
    for (i, blender_xy) in stats[0].projected.iter().enumerate() {
        let rust = &meta["objects"][i]["pixel_coords"];
        let (x, y) = (rust[0].as_f64().unwrap(), rust[1].as_f64().unwrap());
        assert!(
            (x - blender_xy[0]).abs() <= 0.5 && (y - blender_xy[1]).abs() <= 0.5,
            "object {i}: rust ({x}, {y}) vs blender ({}, {})",
            blender_xy[0],
            blender_xy[1]
        );
        assert!((rust[2].as_f64().unwrap() - blender_xy[2]).abs() < 1e-3);
    }

    // Depth of the sphere's nearest point: planar depth of the front surface along the ray
    // through its centre, (|C - O| - r) * cos(angle to the view axis), within 1%.
    let i = objects
        .objects
        .iter()
        .position(|o| o.shape == "sphere")
        .unwrap();
    let sphere = &objects.objects[i];
    let cam = &objects.camera.matrix_world;
    let o = [cam[0][3], cam[1][3], cam[2][3]];
    let fwd = [-cam[0][2], -cam[1][2], -cam[2][2]];
    let d: Vec<f64> = (0..3).map(|k| sphere.location[k] - o[k]).collect();
    let dist = d.iter().map(|v| v * v).sum::<f64>().sqrt();
    let cos = (0..3).map(|k| d[k] / dist * fwd[k]).sum::<f64>();
    let expected = (dist - sphere.scale) * cos;
    let depth = decode_png(&sub.join(format!("{}_depth_0001.png", objects.stem))).unwrap();
    let px = &meta["objects"][i]["pixel_coords"];
    let (x, y) = (
        px[0].as_f64().unwrap() as usize,
        px[1].as_f64().unwrap() as usize,
    );
    let got = depth.data[y * w as usize + x] as f64 * post::DEPTH_SCALE_M;
    assert!(
        (got - expected).abs() / expected < 0.01,
        "sphere depth {got} m vs expected {expected} m"
    );
    assert!(depth.data.contains(&post::DEPTH_BACKGROUND) || depth.data.iter().all(|&v| v < 65535));

    // Objects on a lit floor do cast shadows.
    let shadow = decode_png(&sub.join(format!("{}_shadow_0001.png", objects.stem))).unwrap();
    let shadowed = shadow.data.iter().filter(|&&v| v > 128).count();
    assert!(
        shadowed * 50 > shadow.data.len(),
        "only {shadowed} of {} pixels are shadowed",
        shadow.data.len()
    );

    // Shadow of an empty, lit floor: defined everywhere and ~0.
    let shadow = decode_png(&sub.join(format!("{}_shadow_0001.png", floor.stem))).unwrap();
    let mean = shadow.data.iter().map(|&v| v as f64).sum::<f64>() / shadow.data.len() as f64;
    let dark = shadow.data.iter().filter(|&&v| v > 25).count();
    assert!(mean < 2.0, "mean shadow {mean}/255 on an empty floor");
    assert!(
        dark * 100 < shadow.data.len(),
        "{dark} shadowed pixels on an empty floor"
    );
    // The float passes themselves are finite where it matters.
    let exr =
        clevrtex_render::exr_io::Channels::read(&sub.join(format!("{}_shadow.exr", floor.stem)))
            .unwrap();
    assert!(exr
        .get("ViewLayer.DiffDir.R")
        .unwrap()
        .iter()
        .all(|v| v.is_finite()));
}

/// The shadow pass on a textured, displaced floor (`full8.json`'s cobblestones), tiny and
/// few samples: with no object the pass is <= 0.02 everywhere (the pass up to 0.9, an
/// 8-sample no-shadow render against the final render, reached ~0.6 on such a floor), and
/// with one cube the cube's shadow is there while most of the floor stays exactly 0 (the
/// light with and without object shadows comes from the same samples of one render, so only
/// blocked shadow rays differ); a floor whose material an object shares stays as open (the
/// objects' transparency to shadow rays goes by object, not by material; checked to fail
/// when it went by material).
#[test]
fn shadow_pass_is_zero_on_an_open_floor_and_dark_beside_a_cube() {
    let Some(blender) =
        blender_or_skip("shadow_pass_is_zero_on_an_open_floor_and_dark_beside_a_cube")
    else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let with_index = |mut s: SceneFile, index: u64, objects: usize| {
        s.index = index;
        s.stem = format!("CLEVRTEX_full_{index:06}");
        s.objects.truncate(objects);
        s
    };
    let floor = with_index(fixture("full8", 64, 48, 32), 100, 0);
    let cube = with_index(fixture("full8", 64, 48, 32), 101, 1);
    assert_eq!(cube.objects[0].shape, "cube");
    // The same cube with one shadow sample per render (`render.shadow_samples`).
    let mut one = with_index(fixture("full8", 64, 48, 32), 102, 1);
    one.render.shadow_samples = Some(1);
    // An object that shares the backdrop's material (as in `camo`), far below the floor where
    // it blocks no light: the shadow render makes objects transparent to shadow rays through
    // their materials, and the backdrop must stay opaque (its relief shadows itself in both
    // channels), so the floor is as open as without the object.
    let mut shared = with_index(fixture("full8", 64, 48, 32), 103, 1);
    shared.objects[0].material = shared.backdrop.material.clone();
    shared.objects[0].location = [0.0, 0.0, -50.0];
    let stats = render_fixtures(
        blender,
        dir.path(),
        vec![floor.clone(), cube.clone(), one.clone(), shared.clone()],
    );
    assert!(stats[0].render_s > 0.0 && stats[1].render_s > 0.0);
    let sub = dir.path().join("clevrtex_full/0");
    let shadow = |stem: &str| decode_png(&sub.join(format!("{stem}_shadow_0001.png"))).unwrap();

    let open = shadow(&floor.stem);
    let max = open.data.iter().copied().max().unwrap();
    assert!(
        f64::from(max) / 255.0 <= 0.02,
        "open floor: shadow up to {max}/255"
    );
    assert!(sub.join(format!("{}_shadow.exr", floor.stem)).is_file());
    let max = shadow(&shared.stem).data.iter().copied().max().unwrap();
    assert!(
        f64::from(max) / 255.0 <= 0.02,
        "open floor sharing its material with an object: shadow up to {max}/255"
    );

    let ids = decode_png(&sub.join(format!("{}_flat.png", cube.stem))).unwrap();
    let s = shadow(&cube.stem);
    let on_floor: Vec<u16> = (0..s.data.len())
        .filter(|&i| ids.data[i] == 0)
        .map(|i| s.data[i])
        .collect();
    // Its shadow is soft (four big lights; measured here with 8 shadow samples
    // of a 32-sample render: up to 0.93, 2.4% of the floor >= 0.2).
    let darkest = on_floor.iter().copied().max().unwrap();
    let dark = on_floor.iter().filter(|&&v| v >= 51).count();
    let zero = on_floor.iter().filter(|&&v| v == 0).count();
    assert!(
        darkest >= 102,
        "the cube's shadow reaches only {darkest}/255"
    );
    assert!(
        dark * 100 >= on_floor.len(),
        "only {dark} of {} floor pixels beside the cube have shadow >= 0.2",
        on_floor.len()
    );
    assert!(
        zero * 2 >= on_floor.len(),
        "only {zero} of {} floor pixels are exactly unshadowed",
        on_floor.len()
    );
    // The soft shadow has values between fully lit and fully shadowed, which one sample
    // (`render.shadow_samples` = 1 reaching the bridge) cannot have: each pixel's one light
    // sample is blocked by an object (green 0, red kept: 255) or not (green = red: 0).
    let between = s.data.iter().filter(|&&v| v > 0 && v < 255).count();
    assert!(between > 0, "the default samples give no partial shadow");
    let single = shadow(&one.stem);
    let partial = single.data.iter().filter(|&&v| v > 0 && v < 255).count();
    assert_eq!(
        partial, 0,
        "partial shadow values with one sample ({between} with the default)"
    );
    assert!(single.data.contains(&255), "one sample: no shadow at all");
}

#[test]
fn doctor_reports_blender_and_devices() {
    // Each Blender found, checked on its own (`--blender`); the list names every one.
    let blenders = test_blenders("doctor_reports_blender_and_devices");
    for blender in &blenders {
        let out = clevrtex()
            .arg("doctor")
            .arg("--blender")
            .arg(blender)
            .env("CLEVRTEX_BLENDER", blenders.last().unwrap())
            .output()
            .unwrap();
        let t = text(&out);
        assert_eq!(out.status.code(), Some(0), "{t}");
        assert!(t.contains("version: "), "{t}");
        assert!(t.contains("cycles devices: ") && t.contains("CPU"), "{t}");
        assert!(t.contains("oidn: ") && t.contains("path guiding: "), "{t}");
        for b in &blenders {
            assert!(
                t.contains(&format!("{} [", b.display())),
                "{} not listed: {t}",
                b.display()
            );
        }
        let marked = format!("  * {} [", blender.display());
        assert!(t.contains(&marked), "{marked}: {t}");
        if blender
            .file_name()
            .unwrap()
            .to_string_lossy()
            .starts_with("python")
        {
            assert!(t.contains("(python with bpy)"), "{t}");
        }
    }
}

#[test]
fn a_silent_worker_is_hung_long_before_the_overall_limit() {
    // A wrapper selects the fake's mode without touching this process's environment.
    let dir = tempfile::tempdir().unwrap();
    let wrapper = dir.path().join("blender");
    std::fs::write(
        &wrapper,
        format!(
            "#!/bin/sh\nFAKE_BLENDER_MODE=hang exec '{}' \"$@\"\n",
            fake_blender().display()
        ),
    )
    .unwrap();
    std::process::Command::new("chmod")
        .arg("+x")
        .arg(&wrapper)
        .status()
        .unwrap();
    let bridge = clevrtex_render::BridgeDir::create("{}").unwrap();
    let mut worker = clevrtex_render::Worker::start(&clevrtex_render::WorkerOptions {
        blender: wrapper,
        script: bridge.worker_script(),
        materials: bridge.materials_json(),
        threads: 1,
        startup_timeout: Duration::from_secs(30),
        interrupt: Arc::new(AtomicBool::new(false)),
        device: Default::default(),
    })
    .unwrap();
    worker.set_idle_timeout(Some(Duration::from_secs(1)));
    let t0 = Instant::now();
    let err = worker
        .render(
            &dir.path().join("scene.json"),
            clevrtex_render::Mode::Final,
            dir.path(),
            Duration::from_secs(120),
        )
        .unwrap_err();
    assert!(t0.elapsed() < Duration::from_secs(20), "{:?}", t0.elapsed());
    assert!(err.is_worker_failure());
    assert!(err.to_string().contains("silent for"), "{err}");
    assert!(worker.is_dead());
}

#[test]
fn render_warns_about_hidden_objects_of_fixed_scenes() {
    let Some(blender) = blender_or_skip("render_warns_about_hidden_objects_of_fixed_scenes") else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let mut scene = fixture("tiny3", 64, 48, 1);
    // Deep under the floor: no pixel of object 1 can be seen.
    scene.objects[0].location = [0.0, 0.0, -50.0];
    scene.passes = vec![Pass::Rgb, Pass::Mask];
    let file = dir.path().join("hidden.json");
    std::fs::write(&file, serde_json::to_string(&scene).unwrap()).unwrap();
    let out = clevrtex()
        .args(["render", "--workers", "1", "--blender"])
        .arg(&blender)
        .arg("--out")
        .arg(dir.path().join("out"))
        .arg(&file)
        .output()
        .unwrap();
    let t = text(&out);
    assert_eq!(out.status.code(), Some(0), "{t}");
    assert!(t.contains("warning: object(s) 1 of `"), "{t}");
    assert!(!t.contains("object(s) 1, "), "only object 1 is hidden: {t}");
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

/// `generate` takes its shard from a SLURM array job like `sample` does: task 1 of 2 makes
/// exactly the odd indices (seen in the ledger of a fake Blender that always crashes).
#[test]
fn generate_reads_the_slurm_array_shard() {
    let dir = tempfile::tempdir().unwrap();
    let out = clevrtex()
        .env("FAKE_BLENDER_MODE", "crash")
        .env("SLURM_ARRAY_TASK_ID", "1")
        .env("SLURM_ARRAY_TASK_COUNT", "2")
        .env_remove("SLURM_ARRAY_TASK_MIN")
        .env_remove("SLURM_ARRAY_TASK_STEP")
        .args([
            "generate",
            "--variant",
            "clevr",
            "-n",
            "4",
            "--retries",
            "0",
        ])
        .args(["--width", "64", "--height", "48", "--samples", "1"])
        .args(["--workers", "1", "--out"])
        .arg(dir.path())
        .arg("--blender")
        .arg(fake_blender())
        .output()
        .unwrap();
    let t = text(&out);
    assert_eq!(out.status.code(), Some(3), "{t}");
    let mut indices: Vec<u64> = ledger_lines(dir.path())
        .iter()
        .map(|l| l["index"].as_u64().unwrap())
        .collect();
    indices.sort();
    assert_eq!(indices, vec![1, 3], "{t}");

    // A task id without a task count is refused before anything starts.
    let out = clevrtex()
        .env("SLURM_ARRAY_TASK_ID", "1")
        .env_remove("SLURM_ARRAY_TASK_COUNT")
        .args(["generate", "--variant", "clevr", "-n", "4", "--out"])
        .arg(dir.path().join("other"))
        .arg("--blender")
        .arg(fake_blender())
        .output()
        .unwrap();
    let t = text(&out);
    assert_eq!(out.status.code(), Some(1), "{t}");
    assert!(
        t.contains("SLURM_ARRAY_TASK_COUNT") && t.contains("hint:"),
        "{t}"
    );
    assert!(!dir.path().join("other").exists(), "{t}");
}

/// Bad requests fail before any Blender starts (here there is none), exit 1, naming the flag
/// or key: sizes out of bounds, `--max-attempts 0`, a config that can never fit its objects,
/// and scene files with an impossible size, a far-away object or an absurd number.
#[test]
fn bad_sizes_attempts_configs_and_scene_files_fail_up_front() {
    let dir = tempfile::tempdir().unwrap();
    let gen = |extra: &[&str]| {
        let mut args = vec!["generate", "--variant", "clevr", "-n", "1"];
        args.extend_from_slice(extra);
        args.extend(["--blender", "/no/such/blender", "--out"]);
        let out = clevrtex()
            .args(&args)
            .arg(dir.path().join("out"))
            .output()
            .unwrap();
        (out.status.code(), text(&out))
    };
    let (code, t) = gen(&["--width", "100000", "--height", "100000"]);
    assert_eq!(code, Some(1), "{t}");
    assert!(
        t.contains("`--width 100000` is more than the 8192 allowed"),
        "{t}"
    );
    let (code, t) = gen(&["--max-attempts", "0"]);
    assert_eq!(code, Some(1), "{t}");
    assert!(t.contains("`--max-attempts 0` is not allowed"), "{t}");

    let mut cfg: Value = serde_json::from_str(
        &std::fs::read_to_string(repo_root().join("configs/full.json")).unwrap(),
    )
    .unwrap();
    cfg["objects"]["count"] = serde_json::json!([60, 60]);
    let cfg_path = dir.path().join("crowded.json");
    std::fs::write(&cfg_path, cfg.to_string()).unwrap();
    let out = clevrtex()
        .args([
            "generate",
            "-n",
            "3",
            "--blender",
            "/no/such/blender",
            "--config",
        ])
        .arg(&cfg_path)
        .arg("--out")
        .arg(dir.path().join("out"))
        .output()
        .unwrap();
    let t = text(&out);
    assert_eq!(out.status.code(), Some(1), "{t}");
    assert!(t.contains("cannot place 60 objects"), "{t}");
    assert!(!dir.path().join("out/clevrtex_full/failures.jsonl").exists());

    let scene: Value =
        serde_json::from_str(&std::fs::read_to_string(data("scenes/tiny3.json")).unwrap()).unwrap();
    for (edit, want) in [
        (
            ("/render/width", serde_json::json!(0)),
            "`render.width` = 0: must be between 1 and 8192",
        ),
        (
            ("/objects/1/location/0", serde_json::json!(1e308)),
            "`objects[1].location[0]` = 1e308: numbers must be finite",
        ),
        (
            ("/objects/0/location/1", serde_json::json!(5000.0)),
            "`objects[0].location` = [",
        ),
    ] {
        let mut s = scene.clone();
        *s.pointer_mut(edit.0).unwrap() = edit.1;
        let file = dir.path().join("scenes/bad.json");
        std::fs::create_dir_all(file.parent().unwrap()).unwrap();
        std::fs::write(&file, s.to_string()).unwrap();
        let out = clevrtex()
            .args(["render", "--blender", "/no/such/blender", "--out"])
            .arg(dir.path().join("rendered"))
            .arg(&file)
            .output()
            .unwrap();
        let t = text(&out);
        assert_eq!(out.status.code(), Some(1), "{t}");
        assert!(
            t.contains(&format!("bad scene file `{}`", file.display())),
            "{t}"
        );
        assert!(t.contains(want), "{want}: {t}");
    }
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
    let deadline = Instant::now() + Duration::from_secs(3);
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

/// `clevrtex doctor` with a program that never answers: killed and reported within its
/// `--timeout`, not a hang.
#[test]
fn doctor_reports_a_blender_that_never_answers() {
    let t = Instant::now();
    let out = clevrtex()
        .env("FAKE_BLENDER_MODE", "deaf")
        .args(["doctor", "--timeout", "2", "--blender"])
        .arg(fake_blender())
        .output()
        .unwrap();
    let t_ = text(&out);
    assert_eq!(out.status.code(), Some(1), "{t_}");
    assert!(
        t_.contains("--version` did not answer within 2 s; it was killed"),
        "{t_}"
    );
    assert!(t.elapsed() < Duration::from_secs(20), "{:?}", t.elapsed());
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

/// A worker that never starts is given up on after `--startup-timeout` (not a fixed 120 s),
/// and the hint names that flag, not `--timeout`.
#[test]
fn startup_timeout_is_a_flag_and_its_hint_names_it() {
    let dir = tempfile::tempdir().unwrap();
    let t = Instant::now();
    let out = generate_fake("deaf", dir.path(), &["-n", "1", "--startup-timeout", "1.5"]);
    let t_ = text(&out);
    assert_eq!(out.status.code(), Some(1), "{t_}");
    assert!(
        t_.contains("timed out after 1.5 s while starting up"),
        "{t_}"
    );
    assert!(t_.contains("raise `--startup-timeout`"), "{t_}");
    assert!(t.elapsed() < Duration::from_secs(30), "{:?}", t.elapsed());
}

/// A scene file the bridge cannot build is named as the user's file in the message (not the
/// worker's temporary copy), with what was wrong.
#[test]
fn bridge_errors_name_the_users_scene_file() {
    let Some(blender) = blender_or_skip("bridge_errors_name_the_users_scene_file") else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let mut scene: Value =
        serde_json::from_str(&std::fs::read_to_string(data("scenes/tiny3.json")).unwrap()).unwrap();
    scene["objects"][0]["material"]["name"] = Value::from("no_such_material");
    let file = dir.path().join("scenes/odd.json");
    std::fs::create_dir_all(file.parent().unwrap()).unwrap();
    std::fs::write(&file, scene.to_string()).unwrap();
    let out = clevrtex()
        .args(["render", "--retries", "0", "--blender"])
        .arg(&blender)
        .arg("--out")
        .arg(dir.path().join("out"))
        .arg(&file)
        .output()
        .unwrap();
    let t = text(&out);
    assert_eq!(out.status.code(), Some(3), "{t}");
    assert!(
        t.contains(&format!("(scene file `{}`)", file.display())),
        "{t}"
    );
    assert!(t.contains("no_such_material"), "{t}");
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
