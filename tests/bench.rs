//! Integration tests for `clevrtex bench render` and the quality presets of `generate`.

use std::path::Path;

use serde_json::Value;

use crate::util::{blender_or_skip, bpy_or_skip, clevrtex, crash_once_then, fake_blender, text};

fn bench(out: &Path, extra: &[&str]) -> std::process::Output {
    clevrtex()
        .args(["bench", "render", "--quick", "--scenes", "1"])
        .args(["--width", "24", "--height", "16"])
        .args(["--max-samples", "16", "--reference-samples", "32"])
        .arg("--out")
        .arg(out)
        .args(extra)
        .output()
        .expect("run clevrtex")
}

/// CSV rows as maps from column to value.
fn read_csv(path: &Path) -> Vec<std::collections::BTreeMap<String, String>> {
    let text = std::fs::read_to_string(path).unwrap();
    let mut lines = text.lines();
    let header: Vec<&str> = lines.next().unwrap().split(',').collect();
    lines
        .map(|l| {
            let cells: Vec<&str> = l.split(',').collect();
            assert_eq!(cells.len(), header.len(), "row `{l}`");
            header
                .iter()
                .zip(cells)
                .map(|(h, c)| (h.to_string(), c.to_string()))
                .collect()
        })
        .collect()
}

#[test]
fn bench_render_writes_table_csv_plot_and_caches_references() {
    let Some(_) = blender_or_skip("bench_render_writes_table_csv_plot_and_caches_references")
    else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let out = bench(dir.path(), &[]);
    let t = text(&out);
    assert_eq!(out.status.code(), Some(0), "{t}");
    assert!(t.contains("quick mode: small frames"), "{t}");
    assert!(t.contains("rendering the reference (32 samples)"), "{t}");
    assert!(
        t.contains("setting") && t.contains("rel err") && t.contains("psnr"),
        "{t}"
    );

    let rows = read_csv(&dir.path().join("bench-render.csv"));
    let labels: Vec<&str> = rows.iter().map(|r| r["setting"].as_str()).collect();
    assert_eq!(labels, ["fixed-4", "fixed-16", "adaptive-16-t0.1"], "{t}");
    for r in &rows {
        assert_eq!(r["scene"], "full#0");
        assert_eq!((r["width"].as_str(), r["height"].as_str()), ("24", "16"));
        for col in [
            "wall_s",
            "cycles_s",
            "cycles_cpu_s",
            "rmse_linear",
            "rel_error",
            "psnr_srgb",
        ] {
            let v: f64 = r[col]
                .parse()
                .unwrap_or_else(|_| panic!("{col} = {}", r[col]));
            assert!(v.is_finite() && v > 0.0, "{col} = {v}");
        }
        // Object index and depth come from the first sample of each pixel, so they agree
        // with the reference exactly whatever the sample count.
        assert_eq!(r["mask_equal"], "true", "{r:?}");
        assert_eq!(r["depth_equal"], "true", "{r:?}");
    }
    let err = |i: usize| rows[i]["rel_error"].parse::<f64>().unwrap();
    assert!(err(1) < err(0), "16 samples not better than 4: {rows:?}");

    // The plot, as SVG and PNG.
    let svg = std::fs::read_to_string(dir.path().join("bench-render.svg")).unwrap();
    assert!(
        svg.contains("<svg") && svg.contains("fixed"),
        "svg without curves"
    );
    let png = clevrtex_render::post::decode_png(&dir.path().join("bench-render.png")).unwrap();
    assert_eq!((png.width, png.height), (900, 600));
    assert!(png.data.iter().any(|&v| v < 128), "blank plot");

    // A second run reuses the cached reference (one cache entry, keyed by scene hash).
    let again = bench(dir.path(), &["--only", "fixed-4"]);
    let t2 = text(&again);
    assert_eq!(again.status.code(), Some(0), "{t2}");
    assert!(t2.contains("reference cached"), "{t2}");
    assert!(!t2.contains("rendering the reference"), "{t2}");
    let refs = std::fs::read_dir(dir.path().join("references"))
        .unwrap()
        .count();
    assert_eq!(refs, 1);
    let rows2 = read_csv(&dir.path().join("bench-render.csv"));
    assert_eq!(rows2.len(), 1);
    // Same scene, same settings, same seed: the same error, bit for bit.
    assert_eq!(rows2[0]["rmse_linear"], rows[0]["rmse_linear"]);
}

/// `--blender` given more than once: each Blender against its own reference, one CSV with a
/// `blender` column, the versions side by side (Debian's 3.4 and bpy 4.5 in CI), and a runs
/// folder per place in the list.
#[test]
fn bench_render_puts_several_blenders_side_by_side() {
    let test = "bench_render_puts_several_blenders_side_by_side";
    let (Some(b34), Some(bpy)) = (blender_or_skip(test), bpy_or_skip(test)) else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let out = bench(
        dir.path(),
        &[
            "--only",
            "fixed-4",
            "--blender",
            b34.to_str().unwrap(),
            "--blender",
            bpy.to_str().unwrap(),
        ],
    );
    let t = text(&out);
    assert_eq!(out.status.code(), Some(0), "{t}");
    let rows = read_csv(&dir.path().join("bench-render.csv"));
    let versions: Vec<&str> = rows.iter().map(|r| r["blender"].as_str()).collect();
    assert_eq!(versions.len(), 2, "{rows:?}");
    assert!(versions[0].starts_with("3.4"), "{versions:?}");
    assert!(versions[1].starts_with("4.5"), "{versions:?}");
    for r in &rows {
        let m: f64 = r["reference_mean"].parse().unwrap();
        assert!(m.is_finite() && m > 0.0, "{r:?}");
        assert_eq!(r["mask_equal"], "true", "{r:?}");
        // Both bridges (3.4's Blender, bpy's module) report the render's CPU seconds.
        let cpu: f64 = r["cycles_cpu_s"].parse().unwrap();
        assert!(cpu.is_finite() && cpu > 0.0, "{r:?}");
    }
    // Each version rendered its own reference (the cache is keyed by the version).
    assert_eq!(t.matches("rendering the reference").count(), 2, "{t}");
    let side = t
        .split("Blenders side by side")
        .nth(1)
        .unwrap_or_else(|| panic!("no side-by-side table: {t}"));
    assert!(
        side.contains(&format!("ratios against {}", versions[0])),
        "{t}"
    );
    let line = side
        .lines()
        .find(|l| l.contains(versions[1]))
        .unwrap_or_else(|| panic!("{t}"));
    assert!(
        line.contains("fixed-4") && line.trim_end().ends_with('x'),
        "{line}"
    );
    let runs: Vec<String> = std::fs::read_dir(dir.path().join("runs"))
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    assert_eq!(runs.len(), 2, "{runs:?}");
    assert!(runs.iter().any(|r| r.starts_with("0-3.4")), "{runs:?}");

    // --plot-only redraws the side-by-side table from the CSV alone.
    let again = clevrtex()
        .args(["bench", "render", "--plot-only", "--out"])
        .arg(dir.path())
        .output()
        .unwrap();
    let t2 = text(&again);
    assert_eq!(again.status.code(), Some(0), "{t2}");
    assert!(t2.contains("Blenders side by side"), "{t2}");
}

/// A Blender that dies on its first request is restarted and the render retried, as in
/// `generate`: the bench still finishes.
#[test]
fn bench_render_survives_a_crashed_worker() {
    let Some(blender) = blender_or_skip("bench_render_survives_a_crashed_worker") else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let wrapper = crash_once_then(dir.path(), &format!("'{}'", blender.display()));
    let out = bench(
        &dir.path().join("out"),
        &["--only", "fixed-4", "--blender", wrapper.to_str().unwrap()],
    );
    let t = text(&out);
    assert_eq!(out.status.code(), Some(0), "{t}");
    assert_eq!(t.matches("restarting a Blender worker").count(), 1, "{t}");
    assert!(t.contains("SIGSEGV"), "{t}");
    let rows = read_csv(&dir.path().join("out/bench-render.csv"));
    assert_eq!(rows.len(), 1, "{t}");
    assert_eq!(rows[0]["setting"], "fixed-4");
}

/// A Blender that crashes on every request: `--retries` restarts, then a clear error naming
/// the crash and Blender's last words, exit code 1, no table.
#[test]
fn bench_render_gives_up_on_a_worker_that_keeps_crashing() {
    let dir = tempfile::tempdir().unwrap();
    let out = clevrtex()
        .env("FAKE_BLENDER_MODE", "crash")
        .args([
            "bench",
            "render",
            "--quick",
            "--scenes",
            "1",
            "--retries",
            "2",
        ])
        .args(["--width", "24", "--height", "16", "--out"])
        .arg(dir.path())
        .arg("--blender")
        .arg(fake_blender())
        .output()
        .unwrap();
    let t = text(&out);
    assert_eq!(out.status.code(), Some(1), "{t}");
    assert_eq!(t.matches("restarting a Blender worker").count(), 2, "{t}");
    assert!(t.contains("error: blender worker"), "{t}");
    assert!(t.contains("while rendering `full#0 reference`"), "{t}");
    assert!(t.contains("SIGSEGV"), "{t}");
    assert!(t.contains("segmentation fault while rendering"), "{t}");
    assert!(t.contains("hint: "), "{t}");
    assert!(!dir.path().join("bench-render.csv").exists(), "{t}");
}

#[test]
fn bench_render_rejects_bad_arguments_with_hints() {
    let dir = tempfile::tempdir().unwrap();
    let out = clevrtex()
        .args(["bench", "render", "--scenes", "0", "--out"])
        .arg(dir.path())
        .output()
        .unwrap();
    let t = text(&out);
    assert_eq!(out.status.code(), Some(1), "{t}");
    assert!(t.contains("must be positive") && t.contains("hint:"), "{t}");

    let out = bench(dir.path(), &["--only", "no-such-rung"]);
    let t = text(&out);
    assert_eq!(out.status.code(), Some(1), "{t}");
    assert!(t.contains("no rung of the ladder is left"), "{t}");
    assert!(
        t.contains("hint: raise `--max-samples` or widen `--only`"),
        "{t}"
    );

    let out = clevrtex().args(["bench", "nothing"]).output().unwrap();
    assert_eq!(out.status.code(), Some(2), "{}", text(&out));

    // `--scene`: files not trusted, refused before any Blender is looked for.
    let scenes = dir.path().join("scenes");
    let o = clevrtex()
        .args(["sample", "--variant", "camo", "-n", "1", "--out"])
        .arg(&scenes)
        .output()
        .unwrap();
    assert_eq!(o.status.code(), Some(0), "{}", text(&o));
    let file = scenes.join("clevrtex_camo/0/CLEVRTEX_camo_000000.json");
    let scene_bench = |paths: &[&Path], extra: &[&str]| {
        let mut c = clevrtex();
        c.args(["bench", "render", "--quick", "--out"])
            .arg(dir.path().join("out"))
            .args(extra)
            .env("CLEVRTEX_BLENDER", "/nonexistent/blender");
        for p in paths {
            c.arg("--scene").arg(p);
        }
        c.output().unwrap()
    };
    let o = scene_bench(&[&file], &["--scenes", "2"]);
    assert_eq!(o.status.code(), Some(2), "{}", text(&o));
    let copy = dir.path().join("copy.json");
    std::fs::copy(&file, &copy).unwrap();
    let o = scene_bench(&[&file, &copy], &[]);
    let t = text(&o);
    assert_eq!(o.status.code(), Some(1), "{t}");
    assert!(
        t.contains("are both `CLEVRTEX_camo_000000`") && t.contains("hint:"),
        "{t}"
    );
    let mut v: Value = serde_json::from_slice(&std::fs::read(&file).unwrap()).unwrap();
    v["backdrop"]["material"]["name"] = "no_such_material".into();
    std::fs::write(&copy, serde_json::to_vec(&v).unwrap()).unwrap();
    let o = scene_bench(&[&copy], &[]);
    let t = text(&o);
    assert_eq!(o.status.code(), Some(1), "{t}");
    assert!(
        t.contains("uses material `no_such_material`") && t.contains("--materials"),
        "{t}"
    );
    let o = scene_bench(&[&dir.path().join("absent")], &[]);
    let t = text(&o);
    assert_eq!(o.status.code(), Some(1), "{t}");
    assert!(t.contains("does not exist") && t.contains("hint:"), "{t}");
}

/// `--scene FILE`: the bench renders the scene file given (its stem names the rows), at the
/// bench's size, against its own reference: e.g. the scenes with the most relief.
#[test]
fn bench_render_takes_scene_files() {
    let Some(blender) = blender_or_skip("bench_render_takes_scene_files") else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let scenes = dir.path().join("scenes");
    let o = clevrtex()
        .args([
            "sample",
            "--variant",
            "vbg",
            "-n",
            "1",
            "--start",
            "3",
            "--seed",
            "9",
        ])
        .arg("--out")
        .arg(&scenes)
        .output()
        .unwrap();
    assert_eq!(o.status.code(), Some(0), "{}", text(&o));
    let out = dir.path().join("out");
    let o = clevrtex()
        .args(["bench", "render", "--quick", "--only", "fixed-4"])
        .args([
            "--width",
            "24",
            "--height",
            "16",
            "--reference-samples",
            "16",
        ])
        .arg("--scene")
        .arg(&scenes)
        .arg("--blender")
        .arg(&blender)
        .arg("--out")
        .arg(&out)
        .output()
        .unwrap();
    let t = text(&o);
    assert_eq!(o.status.code(), Some(0), "{t}");
    let rows = read_csv(&out.join("bench-render.csv"));
    assert_eq!(rows.len(), 1, "{t}");
    assert_eq!(rows[0]["scene"], "CLEVRTEX_vbg_000003", "{t}");
    assert_eq!(
        (rows[0]["width"].as_str(), rows[0]["height"].as_str()),
        ("24", "16")
    );
    assert_eq!(rows[0]["mask_equal"], "true", "{rows:?}");
    // The reference is of the file's scene: the cached reference's scene has its layout.
    let refs: Vec<_> = std::fs::read_dir(out.join("references"))
        .unwrap()
        .flatten()
        .collect();
    assert_eq!(refs.len(), 1);
    let rendered: Value =
        serde_json::from_slice(&std::fs::read(refs[0].path().join("scene.json")).unwrap()).unwrap();
    let file = scenes.join("clevrtex_vbg/0/CLEVRTEX_vbg_000003.json");
    let given: Value = serde_json::from_slice(&std::fs::read(file).unwrap()).unwrap();
    for key in ["objects", "backdrop", "camera", "seed", "index"] {
        assert_eq!(rendered[key], given[key], "{key}");
    }
    assert_eq!(rendered["render"]["width"], 24);
}

#[test]
fn generate_quality_preset_sets_samples_threshold_and_bounces() {
    let Some(_) = blender_or_skip("generate_quality_preset_sets_samples_threshold_and_bounces")
    else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let out = clevrtex()
        .args(["generate", "--variant", "clevr", "-n", "2"])
        .args(["--width", "32", "--height", "24", "--passes", "rgb,mask"])
        .args(["--quality", "draft", "--workers", "1", "--out"])
        .arg(dir.path())
        .output()
        .unwrap();
    let t = text(&out);
    assert_eq!(out.status.code(), Some(0), "{t}");
    let draft = clevrtex_scene::quality::Quality::Draft.settings();
    let meta: Value = serde_json::from_str(
        &std::fs::read_to_string(
            dir.path()
                .join("clevrtex_clevr/0/CLEVRTEX_clevr_000000.json"),
        )
        .unwrap(),
    )
    .unwrap();
    let r = &meta["render"];
    assert_eq!(r["samples"].as_u64(), Some(u64::from(draft.samples)), "{r}");
    assert_eq!(
        r["adaptive_threshold"].as_f64().map(|v| v as f32),
        draft.adaptive_threshold,
        "{r}"
    );
    assert_eq!(
        r["max_bounces"].as_u64(),
        Some(u64::from(draft.max_bounces))
    );
    assert_eq!(
        (r["width"].as_u64(), r["height"].as_u64()),
        (Some(32), Some(24))
    );

    let out = clevrtex()
        .args(["generate", "--quality", "ultra", "-n", "1", "--out"])
        .arg(dir.path())
        .output()
        .unwrap();
    let t = text(&out);
    assert_eq!(out.status.code(), Some(2), "{t}");
    assert!(t.contains("unknown quality `ultra`"), "{t}");
    assert!(
        t.contains("hint: use one of draft, fast, standard, high, reference"),
        "{t}"
    );
}

/// `--quality fast` (issue 40): on a Blender with OpenImageDenoise (bpy 4.5) the images are
/// rendered at the preset's samples with the RGB denoised, and say so in their metadata; on one
/// without it (Debian's 3.4) the run is refused before anything is written, with a message
/// naming OIDN and what to do, never rendered noisier than asked. Each Blender's OIDN is what
/// `clevrtex doctor` reports of it.
#[test]
fn fast_preset_denoises_where_oidn_exists_and_is_refused_where_it_does_not() {
    let fast = clevrtex_scene::quality::Quality::Fast.settings();
    for blender in crate::util::test_blenders("fast_preset_denoises_where_oidn_exists") {
        let doctor = clevrtex()
            .arg("doctor")
            .arg("--blender")
            .arg(&blender)
            .output()
            .unwrap();
        let d = text(&doctor);
        // The first `gpus:` line is the Blender asked for; the list of every Blender found
        // follows (another of them may have OIDN).
        let oidn = d
            .lines()
            .find(|l| l.starts_with("gpus:"))
            .is_some_and(|l| l.contains("oidn: yes"));
        assert!(oidn || d.contains("oidn: no"), "{d}");
        let dir = tempfile::tempdir().unwrap();
        let out = clevrtex()
            .args(["generate", "--variant", "clevr", "-n", "1"])
            .args(["--width", "32", "--height", "24", "--passes", "rgb,mask"])
            .args(["--quality", "fast", "--workers", "1", "--blender"])
            .arg(&blender)
            .arg("--out")
            .arg(dir.path())
            .output()
            .unwrap();
        let t = text(&out);
        let sample = dir
            .path()
            .join("clevrtex_clevr/0/CLEVRTEX_clevr_000000.json");
        if oidn {
            assert_eq!(out.status.code(), Some(0), "{}: {t}", blender.display());
            let meta: Value =
                serde_json::from_str(&std::fs::read_to_string(&sample).unwrap()).unwrap();
            let r = &meta["render"];
            assert_eq!(r["denoise"], Value::Bool(true), "{r}");
            assert_eq!(r["samples"].as_u64(), Some(u64::from(fast.samples)), "{r}");
        } else {
            assert_ne!(out.status.code(), Some(0), "{}: {t}", blender.display());
            assert!(
                t.contains("asks for OpenImageDenoise") && t.contains("lacks"),
                "{t}"
            );
            assert!(
                t.contains("hint: render it with a Blender 4.x") && t.contains("--quality draft"),
                "{t}"
            );
            assert!(!sample.exists(), "a sample was written: {t}");
            assert!(
                !dir.path()
                    .join("clevrtex_clevr/0/CLEVRTEX_clevr_000000.png")
                    .exists(),
                "{t}"
            );
        }
    }
}
