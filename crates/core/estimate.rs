//! `clevrtex generate --estimate`: the planner's command. It checks the request, has the
//! render crate's planner (`clevrtex_render::planner`) render a few calibration images of
//! the run's own settings (variant, size, samples, passes, device, workers x threads;
//! visibility pass and rejected layouts included) into a private scratch folder, never into
//! `--out`, and prints the predicted wall time, core or GPU hours and images/hour, alone and
//! as an array of tasks (SLURM `--array`, a Kubernetes Indexed Job's `completions`), with a
//! range from the calibration's spread.

use anyhow::bail;
use clevrtex_render::planner::{self, MAX_CALIBRATE, MIN_CALIBRATE};
use clevrtex_render::pool::Jobs;
use clevrtex_render::RenderError;

use crate::exit::{self, CmdResult};
use crate::interrupt::{self, OnInterrupt};
use crate::run::pool_options;
use crate::run_args::RunArgs;
use clevrtex_render::run_text::format_duration;

/// What `--estimate` was asked for.
pub(crate) struct Request<'a> {
    /// The run's options (`--out` is never written).
    pub run: &'a RunArgs,
    /// The run's jobs; a few are rendered.
    pub jobs: &'a Jobs,
    /// For the first line: variant, size, samples, passes.
    pub what: String,
    /// Calibration images (`--calibrate`), default 2 per worker, at least 4.
    pub calibrate: Option<u32>,
    /// Tasks of an array to predict as well (`--tasks`).
    pub tasks: Option<u64>,
    /// Layout attempts per image.
    pub max_attempts: u32,
    /// The catalogue (built-in plus `--materials`) and the materials the run's config names.
    pub materials: (
        clevrtex_materials::Catalogue,
        std::collections::BTreeSet<String>,
    ),
    /// A suite's sum of predictions (wall seconds, held hours), this one added to it.
    pub sum: Option<&'a std::cell::Cell<(f64, f64)>>,
}

/// Run the planner: calibrate, then print the predictions.
pub(crate) fn run(mut req: Request) -> CmdResult {
    let n = req.jobs.len();
    if let Some(c) = req.calibrate {
        if !(MIN_CALIBRATE..=MAX_CALIBRATE).contains(&c) {
            bail!("`--calibrate {c}` is out of range: the range of a prediction needs at least {MIN_CALIBRATE} images, and more than {MAX_CALIBRATE} is a run, not a calibration\nhint: pass {MIN_CALIBRATE} to {MAX_CALIBRATE}, e.g. `--calibrate 4` (default: 2 per worker, at least 4)");
        }
    }
    if req.tasks == Some(0) {
        bail!("`--tasks 0` is no array\nhint: pass the array's number of tasks, e.g. `--tasks 10`");
    }
    if let Some(t) = req.tasks.filter(|&t| t > n) {
        bail!("`--tasks {t}` is more tasks than the run's {n} image(s): the tasks past the {n}th would have nothing to do\nhint: pass 1 to {n}");
    }
    // Nothing is written into `--out`, but the run planned would be: a place it cannot make
    // its folder (a file, or a file on the way) is refused here as `generate` refuses it.
    let out = &req.run.out;
    if let Some(file) = out
        .ancestors()
        .filter(|p| !p.as_os_str().is_empty())
        .find(|p| std::fs::metadata(p).is_ok_and(|m| !m.is_dir()))
    {
        bail!(
            "`--out {}`: `{}` is not a folder, so the run planned could not write there\nhint: pass a folder (missing ones are created) with `--out`",
            out.display(),
            file.display()
        );
    }
    let blender = clevrtex_render::blender::locate(req.run.blender.as_deref())?;
    let scratch = clevrtex_render::tmp::scratch_dir()?;
    let mut args = req.run.clone();
    args.out = scratch.path().join("out");
    args.overwrite = false;
    let interrupt = interrupt::flag(OnInterrupt::Stop {
        message: "stopping the calibration; nothing was written into `--out`",
    });
    let (catalogue, used) = &mut req.materials;
    let planned = pool_options(
        &args,
        blender,
        scratch.path().join("failures.jsonl"),
        req.max_attempts,
        &interrupt,
        (catalogue, used),
    )?;
    let opts = &planned.opts;
    let k = req
        .calibrate
        .map(|c| c as usize)
        .unwrap_or_else(|| (2 * opts.workers).max(4));
    let k = (k as u64).min(n).max(1) as usize;
    eprintln!(
        "estimate: calibrating on {k} image(s) of {} with {} worker(s) in a scratch folder (nothing is written into `{}`)",
        req.what,
        opts.workers,
        req.run.out.display()
    );
    let made = match planner::calibrate(opts, req.jobs, k, &|line| eprintln!("{line}")) {
        Ok(m) => m,
        Err(RenderError::Interrupted) => {
            eprintln!(
                "error: {}\nhint: nothing was written into `--out`",
                exit::Interrupted
            );
            return Ok(crate::interrupt::exit_code());
        }
        Err(e) => return Err(e.into()),
    };
    let (report, cpu, failed) = (&made.report, made.cpu_s, made.failed);
    let (load_before, load_after) = &made.load;
    let Some(cal) = made.calibration.as_ref() else {
        let why = made
            .first_error
            .clone()
            .unwrap_or_else(|| "no image finished".into());
        bail!("no calibration image could be made, so there is nothing to estimate from: {why}\nhint: `clevrtex generate -n 1` with the same options shows the failure in full");
    };
    let gpus = cal.gpus;
    let (mean, se) = cal.mean_and_se();
    let device = if gpus > 0 {
        format!("{gpus} GPU(s) ({})", opts.devices[0].kind)
    } else {
        "the CPU".to_string()
    };
    println!(
        "estimate for {n} image(s) of {}: {} worker(s) x {} Cycles thread(s) on {device}",
        req.what, cal.workers, cal.threads
    );
    println!(
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
        println!("  note: {failed} calibration image(s) failed; a real run records such images in its failure ledger");
    }
    let held = if gpus > 0 {
        "GPU hours"
    } else {
        "CPU core-hours (workers x threads held)"
    };
    let p = cal.predict(n);
    if let Some(sum) = req.sum {
        let (w, h) = sum.get();
        sum.set((w + p.wall_s, h + p.held_hours));
    }
    println!(
        "this machine: wall {} (range {} - {}), {:.0} images/hour, {:.2} {held}",
        format_duration(p.wall_s),
        format_duration(p.range_s.0),
        format_duration(p.range_s.1),
        p.per_hour,
        p.held_hours
    );
    if let Some(t) = req.tasks {
        let per_task = n.div_ceil(t);
        let q = cal.predict(per_task);
        println!(
            "array of {t} task(s) (SLURM `--array=0-{}`, Kubernetes `completions: {t}`), each on a machine like this one with {per_task} image(s): wall {} (range {} - {}), {:.0} images/hour together, {:.2} {held} in all",
            t - 1,
            format_duration(q.wall_s),
            format_duration(q.range_s.0),
            format_duration(q.range_s.1),
            n as f64 / q.wall_s.max(1e-9) * 3600.0,
            q.held_hours * t as f64
        );
    }
    println!(
        "  range: the calibration mean +- 2 standard errors; the prediction holds for the load measured here (docs/performance.md, \"Planning a run\")"
    );
    drop(scratch);
    Ok(exit::OK)
}
