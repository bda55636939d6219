//! Integration tests of `clevrtex generate` and `clevrtex render` (the dataset they write, what
//! they refuse up front) and `clevrtex doctor`; also the helpers the other modules of the
//! generate topic share (`passes`, `shadow`, `resume`, `ledger`, `blender_failures`).
//!
//! Failure paths use the fake Blender of `tests/fake_blender/` (selected with `--blender`
//! and `FAKE_BLENDER_MODE`); real paths use the real Blender with tiny images, and skip
//! visibly without it (see `util::blender_or_skip`).

use std::path::{Path, PathBuf};
use std::process::Output;
use std::sync::atomic::AtomicBool;
use std::sync::{Arc, Mutex};

use clevrtex_render::pool::{self, Job, PoolEvent, PoolOptions, SampleStats};
use clevrtex_render::post::decode_png;
use clevrtex_scene::{Pass, SceneFile};
use serde_json::Value;

use crate::util::{blender_or_skip, clevrtex, data, repo_root, test_blenders, text};

pub(crate) fn fake_blender() -> PathBuf {
    repo_root().join("tests/fake_blender/blender")
}

/// `clevrtex generate` of one tiny clevr image with the fake Blender in `mode`.
pub(crate) fn generate_fake(mode: &str, out: &Path, extra: &[&str]) -> Output {
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
pub(crate) fn generate_tiny_rgb_mask(blender: &Path, out: &Path) -> Output {
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

pub(crate) fn ledger_lines(out: &Path) -> Vec<Value> {
    let path = out.join("clevrtex_clevr/failures.jsonl");
    std::fs::read_to_string(&path)
        .unwrap_or_default()
        .lines()
        .map(|l| serde_json::from_str(l).expect("ledger lines are JSON"))
        .collect()
}

/// Every file under `dir`, relative, sorted.
pub(crate) fn files_under(dir: &Path) -> Vec<String> {
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

pub(crate) fn read_json(path: &Path) -> Value {
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
        assert!(t.contains("bridge phases"), "{t}");
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
        // The dataset card, and the guard of its writers (an empty file that stays).
        expected.push("DATASET_CARD.md".to_string());
        expected.push(".clevrtex-card.lock".to_string());
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

pub(crate) fn fixture(name: &str, width: u32, height: u32, samples: u32) -> SceneFile {
    let text = std::fs::read_to_string(data(&format!("scenes/{name}.json"))).unwrap();
    let mut scene: SceneFile = serde_json::from_str(&text).unwrap();
    scene.render.width = width;
    scene.render.height = height;
    scene.render.samples = samples;
    scene
}

/// Render fixture scenes through the library pool (one worker), returning the stats.
pub(crate) fn render_fixtures(
    blender: PathBuf,
    out: &Path,
    scenes: Vec<SceneFile>,
) -> Vec<SampleStats> {
    let jobs: Vec<Job> = scenes
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
        user_materials: Default::default(),
        config_hash: None,
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
        recycle: Default::default(),
        resume: None,
        keep: None,
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
        t.contains("`--width 100000` is more than the 4096 allowed"),
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
            "`render.width` = 0: must be between 1 and 4096",
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

/// Issue 34: counts and limits were aborts or panics: `generate -n 100000000` (the dataset
/// cap) allocated 12.8 GB of jobs up front and aborted, `sample` had no cap, `--timeout 1e300`
/// panicked, `verify --jobs 100000` started 100,000 threads. Each is a clear refusal now (or,
/// for `-n 100000000`, a run that reaches Blender within 2 GB of address space).
#[test]
fn counts_and_limits_are_refused_not_aborted() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("out");
    let missing = dir.path().join("no-blender");
    // The whole cap: jobs are made lazily, so the run gets as far as looking for Blender.
    let (code, t) = crate::util::run_limited(
        &[
            "generate".as_ref(),
            "-n".as_ref(),
            "100000000".as_ref(),
            "--out".as_ref(),
            out.as_os_str(),
            "--blender".as_ref(),
            missing.as_os_str(),
        ],
        &[],
        120,
    );
    assert_eq!(code, Some(1), "{t}");
    assert!(t.contains("no-blender"), "{t}");
    // A value outside a flag's fixed range: refused by the parser (exit 2), naming the range.
    let usage = |args: &[&str], says: &str| {
        let o = clevrtex().args(args).output().unwrap();
        let t = text(&o);
        assert_eq!(o.status.code(), Some(2), "{args:?}: {t}");
        assert!(t.contains(says), "{args:?}: {t}");
    };
    // A limit checked after parsing: exit 1, naming the flag, with a hint.
    let refused = |args: &[&str], says: &str| {
        let o = clevrtex().args(args).output().unwrap();
        let t = text(&o);
        assert_eq!(o.status.code(), Some(1), "{args:?}: {t}");
        assert!(t.contains(says), "{args:?}: {t}");
        assert_hint_is_last(&t);
    };
    let o = out.to_str().unwrap();
    let nb = missing.to_str().unwrap();
    usage(
        &["generate", "-n", "100000001", "--out", o],
        "0..=100000000",
    );
    usage(
        &["sample", "--variant", "full", "-n", "100000001", "--out", o],
        "0..=100000000",
    );
    usage(
        &[
            "sample",
            "--variant",
            "full",
            "-n",
            "1",
            "--total",
            "1e9",
            "--out",
            o,
        ],
        "--total",
    );
    usage(&["verify", "--jobs", "100000", o], "1..=1024");
    usage(
        &[
            "sample",
            "--variant",
            "full",
            "-n",
            "1",
            "-j",
            "0",
            "--out",
            o,
        ],
        "1..=1024",
    );
    usage(
        &["generate", "-n", "1", "--threads", "5000", "--out", o],
        "1..=1024",
    );
    usage(
        &["generate", "-n", "1", "--retries", "1000", "--out", o],
        "0..=100",
    );
    refused(
        &[
            "generate",
            "-n",
            "1",
            "--timeout",
            "1e300",
            "--blender",
            nb,
            "--out",
            o,
        ],
        "`--timeout 1e300` must be a positive number of seconds, at most 604800",
    );
    refused(
        &[
            "generate",
            "-n",
            "1",
            "--timeout=-1",
            "--blender",
            nb,
            "--out",
            o,
        ],
        "`--timeout -1` must be a positive",
    );
    refused(
        &[
            "generate",
            "-n",
            "1",
            "--startup-timeout",
            "1e300",
            "--blender",
            nb,
            "--out",
            o,
        ],
        "`--startup-timeout 1e300`",
    );
    refused(
        &[
            "generate",
            "-n",
            "1",
            "--workers",
            "100000",
            "--blender",
            nb,
            "--out",
            o,
        ],
        "`--workers 100000` is more than the 1024 allowed",
    );
    refused(
        &[
            "generate",
            "-n",
            "1",
            "--max-attempts",
            "100000",
            "--out",
            o,
        ],
        "`--max-attempts 100000` is more than the 1000 allowed",
    );
    refused(
        &["doctor", "--timeout", "1e300"],
        "`--timeout 1e300` must be a positive number of seconds",
    );
    // `--start` + `-n` past the cap: refused by the command, naming both.
    for cmd in [&["generate"][..], &["sample", "--variant", "full"]] {
        let mut args = cmd.to_vec();
        args.extend(["--start", "99999999", "-n", "2", "--out", o]);
        let o = clevrtex().args(&args).output().unwrap();
        let t = text(&o);
        assert_eq!(o.status.code(), Some(1), "{args:?}: {t}");
        assert!(t.contains("past the dataset cap of 100000000"), "{t}");
        assert_hint_is_last(&t);
    }
    assert!(!out.join("clevrtex_full").exists());
}
