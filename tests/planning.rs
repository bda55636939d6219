//! Planning a run (issue 35): `generate --estimate` (the planner: calibration images in a
//! scratch folder, predictions, refusals, nothing written into `--out`) and the progress
//! lines of a batch log (stderr not a terminal: the tests' pipes).

use std::path::Path;

use crate::generate::fake_blender;
use crate::util::{blender_or_skip, clevrtex, text};

/// `clevrtex generate` of `clevr` at 32x24, 1 sample, rgb and mask, with `blender`.
fn tiny(blender: &Path, out: &Path, extra: &[&str]) -> std::process::Output {
    clevrtex()
        .args([
            "generate",
            "--variant",
            "clevr",
            "--width",
            "32",
            "--height",
            "24",
        ])
        .args(["--samples", "1", "--passes", "rgb,mask", "--out"])
        .arg(out)
        .arg("--blender")
        .arg(blender)
        .args(extra)
        .output()
        .expect("run clevrtex")
}

/// The `progress:` lines of a run's stderr.
fn progress_lines(out: &std::process::Output) -> Vec<String> {
    String::from_utf8_lossy(&out.stderr)
        .lines()
        .filter(|l| l.starts_with("progress: "))
        .map(str::to_string)
        .collect()
}

#[test]
fn batch_logs_show_rate_eta_and_failures_so_far() {
    // Every image fails (a worker that crashes on its first request, no retries): the
    // progress line counts the failures.
    let tmp = tempfile::tempdir().unwrap();
    let out = crate::generate::generate_fake("crash", tmp.path(), &["-n", "3", "--retries", "0"]);
    assert_eq!(out.status.code(), Some(3), "{}", text(&out));
    let lines = progress_lines(&out);
    assert_eq!(
        lines.len(),
        1,
        "one line at the end of 3 images: {}",
        text(&out)
    );
    assert!(
        lines[0].starts_with("progress: 3/3 images (0 written, 3 failed), 0 img/h, elapsed "),
        "{}",
        lines[0]
    );
    assert!(lines[0].ends_with("ETA 0s"), "{}", lines[0]);
}

#[test]
fn batch_logs_of_a_real_run_show_progress_and_skips() {
    let Some(blender) =
        blender_or_skip("planning::batch_logs_of_a_real_run_show_progress_and_skips")
    else {
        return;
    };
    let tmp = tempfile::tempdir().unwrap();
    let out = tiny(&blender, tmp.path(), &["-n", "2", "--workers", "1"]);
    assert_eq!(out.status.code(), Some(0), "{}", text(&out));
    // One line at the end (and one a minute before it, on a machine slow enough).
    let lines = progress_lines(&out);
    let l = lines
        .last()
        .unwrap_or_else(|| panic!("no progress line: {}", text(&out)));
    assert!(
        l.starts_with("progress: 2/2 images (2 written, 0 failed), "),
        "{l}"
    );
    assert!(l.ends_with(", ETA 0s"), "{l}");
    let rate: f64 = l
        .split(", ")
        .find_map(|p| p.strip_suffix(" img/h"))
        .and_then(|r| r.parse().ok())
        .unwrap_or_else(|| panic!("no rate in {l}"));
    assert!(rate > 0.0, "{l}");
    // Grown to 3: two already complete, one made; the line says so.
    let out = tiny(
        &blender,
        tmp.path(),
        &["-n", "3", "--workers", "1", "--allow-split-mismatch"],
    );
    assert_eq!(out.status.code(), Some(0), "{}", text(&out));
    let lines = progress_lines(&out);
    assert!(
        lines
            .last()
            .is_some_and(|l| l
                .starts_with("progress: 3/3 images (1 written, 2 already complete, 0 failed), ")),
        "{}",
        text(&out)
    );
}

#[test]
fn estimate_predicts_from_calibration_and_writes_nothing_into_out() {
    let Some(blender) =
        blender_or_skip("planning::estimate_predicts_from_calibration_and_writes_nothing_into_out")
    else {
        return;
    };
    let tmp = tempfile::tempdir().unwrap();
    let out_dir = tmp.path().join("out");
    let out = tiny(
        &blender,
        &out_dir,
        &[
            "-n",
            "1000",
            "--estimate",
            "--calibrate",
            "2",
            "--workers",
            "1",
            "--tasks",
            "10",
        ],
    );
    let t = text(&out);
    assert_eq!(out.status.code(), Some(0), "{t}");
    assert!(!out_dir.exists(), "an estimate wrote into `--out`: {t}");
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(
        stdout.contains("estimate for 1000 image(s) of `clevr` at 32x24, 1 samples, passes rgb,mask: 1 worker(s) x "),
        "{t}"
    );
    assert!(stdout.contains("calibration: 2 image(s) in "), "{t}");
    let machine = stdout
        .lines()
        .find(|l| l.starts_with("this machine: wall "))
        .unwrap_or_else(|| panic!("{t}"));
    assert!(
        machine.contains("images/hour") && machine.contains("CPU core-hours"),
        "{machine}"
    );
    assert!(
        stdout.contains("array of 10 task(s) (SLURM `--array=0-9`, Kubernetes `completions: 10`), each on a machine like this one with 100 image(s): wall "),
        "{t}"
    );
}

#[test]
fn estimate_refuses_bad_input_before_writing_anything() {
    let tmp = tempfile::tempdir().unwrap();
    let out_dir = tmp.path().join("out");
    let run = |extra: &[&str]| {
        clevrtex()
            .env("FAKE_BLENDER_MODE", "crash")
            .env_remove("CLEVRTEX_BLENDER")
            .args(["generate", "--variant", "clevr", "--estimate", "--out"])
            .arg(&out_dir)
            .arg("--blender")
            .arg(fake_blender())
            .args(extra)
            .output()
            .unwrap()
    };
    let o = run(&["-n", "0"]);
    assert_eq!(o.status.code(), Some(1), "{}", text(&o));
    assert!(
        text(&o).contains("`-n 0` asks for no images\nhint: "),
        "{}",
        text(&o)
    );
    // A device that is not there: the fake Blender reports no GPU.
    let o = run(&["-n", "10", "--device", "optix"]);
    assert_eq!(o.status.code(), Some(1), "{}", text(&o));
    assert!(
        text(&o).contains("`--device optix`: Blender reports no OPTIX device (found: no GPU)"),
        "{}",
        text(&o)
    );
    let o = run(&["-n", "10", "--tasks", "0"]);
    assert_eq!(o.status.code(), Some(1), "{}", text(&o));
    assert!(
        text(&o).contains("`--tasks 0` is no array\nhint: "),
        "{}",
        text(&o)
    );
    // Calibration that cannot render (every worker crashes): a clear error, not a guess.
    let o = run(&["-n", "10", "--calibrate", "2", "--retries", "0"]);
    assert_eq!(o.status.code(), Some(1), "{}", text(&o));
    assert!(
        text(&o)
            .contains("no calibration image could be made, so there is nothing to estimate from"),
        "{}",
        text(&o)
    );
    // A variant whose layouts cannot be placed.
    let mut cfg: serde_json::Value = serde_json::from_str(
        &std::fs::read_to_string(crate::util::repo_root().join("configs/full.json")).unwrap(),
    )
    .unwrap();
    cfg["name"] = "crowded".into();
    cfg["objects"]["count"] = serde_json::json!([100, 100]);
    let cfg_path = tmp.path().join("crowded.json");
    std::fs::write(&cfg_path, cfg.to_string()).unwrap();
    let o = clevrtex()
        .args(["generate", "-n", "10", "--estimate", "--config"])
        .arg(&cfg_path)
        .arg("--out")
        .arg(&out_dir)
        .arg("--blender")
        .arg(fake_blender())
        .output()
        .unwrap();
    assert_eq!(o.status.code(), Some(1), "{}", text(&o));
    assert!(
        text(&o).contains("cannot place 100 objects"),
        "{}",
        text(&o)
    );
    assert!(!out_dir.exists(), "a refused estimate wrote into `--out`");
    // `--calibrate` and `--tasks` belong to `--estimate`.
    let o = clevrtex()
        .args(["generate", "-n", "1", "--tasks", "3", "--out"])
        .arg(&out_dir)
        .output()
        .unwrap();
    assert_eq!(o.status.code(), Some(2), "{}", text(&o));
}

/// Issue 42, minor findings: `--tasks 100000000000` printed an array of 10^11 tasks for 10
/// images, `--calibrate` had no range (1 gave a zero-width range, 100000 started 100,000
/// renders), and an `--out` that is a regular file was accepted. Each is refused up front
/// (exit 1, before Blender is looked for) with its range.
#[test]
fn estimate_refuses_numbers_out_of_range_and_an_out_that_is_a_file() {
    let tmp = tempfile::tempdir().unwrap();
    let file = tmp.path().join("a-file");
    std::fs::write(&file, b"mine").unwrap();
    let run = |out: &Path, extra: &[&str]| {
        clevrtex()
            .env_remove("CLEVRTEX_BLENDER")
            .args(["generate", "--variant", "clevr", "--estimate", "-n", "10"])
            .arg("--out")
            .arg(out)
            .args(["--blender", "/nonexistent/blender"])
            .args(extra)
            .output()
            .unwrap()
    };
    let out = tmp.path().join("out");
    for (extra, want) in [
        (
            &["--tasks", "100000000000"][..],
            "`--tasks 100000000000` is more tasks than the run's 10 image(s)",
        ),
        (&["--tasks", "11"][..], "hint: pass 1 to 10"),
        (&["--calibrate", "1"][..], "`--calibrate 1` is out of range"),
        (&["--calibrate", "101"][..], "hint: pass 2 to 100"),
    ] {
        let o = run(&out, extra);
        assert_eq!(o.status.code(), Some(1), "{extra:?}: {}", text(&o));
        assert!(text(&o).contains(want), "{extra:?}: {}", text(&o));
    }
    for out in [file.clone(), file.join("below")] {
        let o = run(&out, &[]);
        assert_eq!(o.status.code(), Some(1), "{}", text(&o));
        assert!(
            text(&o).contains(&format!("`{}` is not a folder", file.display())),
            "{}",
            text(&o)
        );
    }
    assert_eq!(std::fs::read(&file).unwrap(), b"mine");
    assert!(!out.exists());
}
