//! `generate --estimate`'s request checked ([`check_request`]) and its predictions as text
//! ([`report`]: the command prints it), over the planner's calibration (`crate::planner`).

use std::fmt::Write;
use std::path::Path;

use crate::planner::{Calibrated, Prediction, MAX_CALIBRATE, MIN_CALIBRATE};
use crate::pool::PoolOptions;
use crate::run_text::format_duration;

/// `--calibrate`, `--tasks` for a run of `n` images and `--out` checked before anything runs.
pub fn check_request(
    calibrate: Option<u32>,
    tasks: Option<u64>,
    n: u64,
    out: &Path,
) -> Result<(), String> {
    if let Some(c) = calibrate {
        if !(MIN_CALIBRATE..=MAX_CALIBRATE).contains(&c) {
            return Err(format!("`--calibrate {c}` is out of range: the range of a prediction needs at least {MIN_CALIBRATE} images, and more than {MAX_CALIBRATE} is a run, not a calibration\nhint: pass {MIN_CALIBRATE} to {MAX_CALIBRATE}, e.g. `--calibrate 4` (default: 2 per worker, at least 4)"));
        }
    }
    if tasks == Some(0) {
        return Err(
            "`--tasks 0` is no array\nhint: pass the array's number of tasks, e.g. `--tasks 10`"
                .into(),
        );
    }
    if let Some(t) = tasks.filter(|&t| t > n) {
        return Err(format!("`--tasks {t}` is more tasks than the run's {n} image(s): the tasks past the {n}th would have nothing to do\nhint: pass 1 to {n}"));
    }
    // Nothing is written into `--out`, but the run planned would be: a place it cannot make
    // its folder (a file, or a file on the way) is refused here as `generate` refuses it.
    if let Some(file) = out
        .ancestors()
        .filter(|p| !p.as_os_str().is_empty())
        .find(|p| std::fs::metadata(p).is_ok_and(|m| !m.is_dir()))
    {
        return Err(format!(
            "`--out {}`: `{}` is not a folder, so the run planned could not write there\nhint: pass a folder (missing ones are created) with `--out`",
            out.display(),
            file.display()
        ));
    }
    Ok(())
}

/// Calibration images: `--calibrate`, else 2 per worker and at least 4; at most the run's `n`.
pub fn calibration_size(calibrate: Option<u32>, workers: usize, n: u64) -> usize {
    let k = calibrate
        .map(|c| c as usize)
        .unwrap_or_else(|| (2 * workers).max(4));
    (k as u64).min(n).max(1) as usize
}

/// The predictions for `n` images of `what` (and an array of `tasks` tasks) from `made` with
/// the pool `opts`, as printed, with the prediction for `n`; an error when no calibration
/// image was made.
pub fn report(
    made: &Calibrated,
    opts: &PoolOptions,
    (n, what): (u64, &str),
    tasks: Option<u64>,
) -> Result<(String, Prediction), String> {
    let (report, cpu, failed) = (&made.report, made.cpu_s, made.failed);
    let (load_before, load_after) = &made.load;
    let Some(cal) = made.calibration.as_ref() else {
        let why = made
            .first_error
            .clone()
            .unwrap_or_else(|| "no image finished".into());
        return Err(format!("no calibration image could be made, so there is nothing to estimate from: {why}\nhint: `clevrtex generate -n 1` with the same options shows the failure in full"));
    };
    let mut out = String::new();
    let gpus = cal.gpus;
    let (mean, se) = cal.mean_and_se();
    let device = if gpus > 0 {
        format!("{gpus} GPU(s) ({})", opts.devices[0].kind)
    } else {
        "the CPU".to_string()
    };
    let _ = writeln!(
        out,
        "estimate for {n} image(s) of {what}: {} worker(s) x {} Cycles thread(s) on {device}",
        cal.workers, cal.threads
    );
    let _ = writeln!(
        out,
        "calibration: {} image(s) in {:.1} s wall: {mean:.1} s per image per worker (standard error {se:.1} s, spread {:.1}-{:.1} s), {} rejected layout(s); Blender start {:.1} s per worker{}; load average {} before, {} after",
        cal.per_image.len(),
        report.wall_s,
        cal.per_image.iter().copied().fold(f64::INFINITY, f64::min),
        cal.per_image.iter().copied().fold(0.0, f64::max),
        report.rejects,
        cal.start_s,
        cpu.filter(|c| *c > 0.0 && gpus == 0)
            .map(|c| format!(
                "; {:.1} CPU-s per image (Blender's, start included)",
                c / cal.per_image.len() as f64
            ))
            .unwrap_or_default(),
        load_before,
        load_after
    );
    if failed > 0 {
        let _ = writeln!(out, "  note: {failed} calibration image(s) failed; a real run records such images in its failure ledger");
    }
    let held = if gpus > 0 {
        "GPU hours"
    } else {
        "CPU core-hours (workers x threads held)"
    };
    let p = cal.predict(n);
    let _ = writeln!(
        out,
        "this machine: wall {} (range {} - {}), {:.0} images/hour, {:.2} {held}",
        format_duration(p.wall_s),
        format_duration(p.range_s.0),
        format_duration(p.range_s.1),
        p.per_hour,
        p.held_hours
    );
    if let Some(t) = tasks {
        let per_task = n.div_ceil(t);
        let q = cal.predict(per_task);
        let _ = writeln!(
            out,
            "array of {t} task(s) (SLURM `--array=0-{}`, Kubernetes `completions: {t}`), each on a machine like this one with {per_task} image(s): wall {} (range {} - {}), {:.0} images/hour together, {:.2} {held} in all",
            t - 1,
            format_duration(q.wall_s),
            format_duration(q.range_s.0),
            format_duration(q.range_s.1),
            n as f64 / q.wall_s.max(1e-9) * 3600.0,
            q.held_hours * t as f64
        );
    }
    let _ = writeln!(
        out,
        "  range: the calibration mean +- 2 standard errors; the prediction holds for the load measured here (docs/performance.md, \"Planning a run\")"
    );
    Ok((out, p))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn requests_are_checked_and_calibration_sized() {
        let dir = tempfile::tempdir().unwrap();
        let out = dir.path().join("out");
        assert!(check_request(Some(4), Some(2), 10, &out).is_ok());
        let e = check_request(Some(1), None, 10, &out).unwrap_err();
        assert!(e.contains("`--calibrate 1` is out of range"), "{e}");
        assert!(check_request(None, Some(0), 10, &out)
            .unwrap_err()
            .contains("`--tasks 0`"));
        assert!(check_request(None, Some(11), 10, &out)
            .unwrap_err()
            .contains("`--tasks 11`"));
        let file = dir.path().join("file");
        std::fs::write(&file, b"x").unwrap();
        let e = check_request(None, None, 10, &file.join("out")).unwrap_err();
        assert!(e.contains("is not a folder"), "{e}");
        // 2 per worker, at least 4, at most the run.
        assert_eq!(calibration_size(None, 1, 100), 4);
        assert_eq!(calibration_size(None, 3, 100), 6);
        assert_eq!(calibration_size(None, 3, 5), 5);
        assert_eq!(calibration_size(Some(2), 8, 100), 2);
    }
}
