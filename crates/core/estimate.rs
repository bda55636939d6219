//! `clevrtex generate --estimate`: the planner. It renders a few calibration images of the
//! run's own settings (variant, size, samples, passes, device, workers x threads; visibility
//! pass and rejected layouts included) into a private scratch folder, never into `--out`, and
//! predicts the run's wall time, core or GPU hours and images/hour, alone and as an array of
//! tasks (SLURM `--array`, a Kubernetes Indexed Job's `completions`), with a range from the
//! calibration's spread.

use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::Mutex;

use anyhow::bail;
use clevrtex_render::pool::{self, Job, Jobs, PoolEvent};
use clevrtex_render::RenderError;

use crate::exit::{self, CmdResult};
use crate::interrupt::{self, OnInterrupt};
use crate::run::{format_duration, pool_options};
use crate::run_args::RunArgs;

/// The fewest calibration images (`--calibrate`): one gives no spread, so a zero-width range.
pub(crate) const MIN_CALIBRATE: u32 = 2;
/// The most calibration images (`--calibrate`): more is a run, not a calibration.
pub(crate) const MAX_CALIBRATE: u32 = 100;

/// What the calibration measured.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct Calibration {
    /// Seconds each calibration image took its worker (visibility pass, rejects, render,
    /// writing), with `workers` workers running at once.
    pub per_image: Vec<f64>,
    /// Seconds one worker took to start (Blender and the bridge), on average.
    pub start_s: f64,
    /// Workers running at once.
    pub workers: usize,
    /// Cycles threads per worker.
    pub threads: u32,
    /// GPUs the workers are spread over (0: the CPU).
    pub gpus: usize,
}

/// A predicted run: wall seconds with a low and high end, and what it holds.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct Prediction {
    /// Images per worker (the most any worker gets).
    pub images_per_worker: u64,
    /// Predicted wall seconds.
    pub wall_s: f64,
    /// Low and high end: the calibration mean +- 2 standard errors.
    pub range_s: (f64, f64),
    /// Images per hour of this run.
    pub per_hour: f64,
    /// Hours of what the run holds: GPU hours, or CPU core-hours (workers x threads).
    pub held_hours: f64,
}

impl Calibration {
    /// Mean seconds per image per worker, and its standard error (0 with one image).
    pub fn mean_and_se(&self) -> (f64, f64) {
        let k = self.per_image.len() as f64;
        let mean = self.per_image.iter().sum::<f64>() / k.max(1.0);
        if self.per_image.len() < 2 {
            return (mean, 0.0);
        }
        let var = self
            .per_image
            .iter()
            .map(|s| (s - mean).powi(2))
            .sum::<f64>()
            / (k - 1.0);
        (mean, (var / k).sqrt())
    }

    /// `n` images on one machine like the calibration's: each worker starts once, then makes
    /// its share of the images one after another.
    pub fn predict(&self, n: u64) -> Prediction {
        let w = self.workers.max(1) as u64;
        let per_worker = n.div_ceil(w);
        let (mean, se) = self.mean_and_se();
        let at = |m: f64| self.start_s + per_worker as f64 * m;
        let wall_s = at(mean);
        let held = if self.gpus > 0 {
            self.gpus.min(self.workers.max(1)) as f64
        } else {
            (self.workers.max(1) as u64 * u64::from(self.threads.max(1))) as f64
        };
        Prediction {
            images_per_worker: per_worker,
            wall_s,
            range_s: (at((mean - 2.0 * se).max(0.0)), at(mean + 2.0 * se)),
            per_hour: n as f64 / wall_s.max(1e-9) * 3600.0,
            held_hours: wall_s / 3600.0 * held,
        }
    }
}

/// CPU seconds (user + system) of this process's waited-for children so far: fields 16 and
/// 17 (`cutime`, `cstime`) of `/proc/self/stat`, in the kernel's fixed `USER_HZ` of 100 ticks
/// per second; `None` where there is no `/proc`.
fn children_cpu_s() -> Option<f64> {
    let stat = std::fs::read_to_string("/proc/self/stat").ok()?;
    let rest = &stat[stat.rfind(')')? + 1..];
    let f: Vec<&str> = rest.split_whitespace().collect();
    // `rest` starts at field 3.
    let ticks: f64 = f.get(13)?.parse::<f64>().ok()? + f.get(14)?.parse::<f64>().ok()?;
    Some(ticks / 100.0)
}

/// `k` of `jobs`, spread evenly over them (the first, then every `len / k`-th); made one at a
/// time, so a run of 100 million images is planned without a list of its jobs.
fn spread(jobs: &Jobs, k: usize) -> Vec<Job> {
    let len = jobs.len();
    let k = (k as u64).min(len).max(1);
    let picks: std::collections::BTreeSet<u64> = (0..k)
        .map(|i| (i as u128 * len as u128 / k as u128) as u64)
        .collect();
    picks.into_iter().map(|i| jobs.get(i)).collect()
}

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
    let (opts, _user) = pool_options(
        &args,
        blender,
        scratch.path().join("failures.jsonl"),
        req.max_attempts,
        &interrupt,
        (catalogue, used),
    )?;
    let k = req
        .calibrate
        .map(|c| c as usize)
        .unwrap_or_else(|| (2 * opts.workers).max(4));
    let jobs = spread(req.jobs, k);
    let k = jobs.len();
    eprintln!(
        "estimate: calibrating on {k} image(s) of {} with {} worker(s) in a scratch folder (nothing is written into `{}`)",
        req.what,
        opts.workers,
        req.run.out.display()
    );
    let per_image = Mutex::new(Vec::new());
    let (ended, failed) = (AtomicU64::new(0), AtomicU64::new(0));
    let first_error = Mutex::new(None::<String>);
    let on_event = |ev: &PoolEvent| match ev {
        PoolEvent::Done { sample } => {
            let s = sample.visibility_s + sample.reject_s + sample.final_request_s + sample.post_s;
            per_image.lock().unwrap_or_else(|e| e.into_inner()).push(s);
            let e = ended.fetch_add(1, Ordering::Relaxed) + 1;
            eprintln!("calibration: {e}/{k} images ({s:.1} s)");
        }
        PoolEvent::Failed { index, error } => {
            failed.fetch_add(1, Ordering::Relaxed);
            let e = ended.fetch_add(1, Ordering::Relaxed) + 1;
            eprintln!("calibration: {e}/{k} images (image {index} failed: {error})");
            first_error
                .lock()
                .unwrap_or_else(|e| e.into_inner())
                .get_or_insert_with(|| error.to_string());
        }
        _ => {}
    };
    let cpu_before = children_cpu_s();
    let load_before = load_average();
    let report = match pool::run(&opts, Jobs::from(jobs), &on_event) {
        Ok(r) => r,
        Err(RenderError::Interrupted) => {
            eprintln!(
                "error: {}\nhint: nothing was written into `--out`",
                exit::Interrupted
            );
            return Ok(crate::interrupt::exit_code());
        }
        Err(e) => return Err(e.into()),
    };
    let cpu = cpu_before.zip(children_cpu_s()).map(|(a, b)| b - a);
    let per_image = per_image.into_inner().unwrap_or_else(|e| e.into_inner());
    if per_image.is_empty() {
        let why = first_error
            .into_inner()
            .unwrap_or_else(|e| e.into_inner())
            .unwrap_or_else(|| "no image finished".into());
        bail!("no calibration image could be made, so there is nothing to estimate from: {why}\nhint: `clevrtex generate -n 1` with the same options shows the failure in full");
    }
    let gpus = opts.devices.iter().filter(|d| d.is_gpu()).count();
    let cal = Calibration {
        per_image,
        start_s: report.blender_start_s / report.worker_starts.max(1) as f64,
        workers: report.workers,
        threads: report.threads,
        gpus,
    };
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
        load_average()
    );
    let failed = failed.load(Ordering::Relaxed);
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

/// `/proc/loadavg`'s 1-minute load, for the record (`?` where unknown).
fn load_average() -> String {
    std::fs::read_to_string("/proc/loadavg")
        .ok()
        .and_then(|t| t.split_whitespace().next().map(str::to_string))
        .unwrap_or_else(|| "?".into())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn cal(per_image: Vec<f64>, workers: usize, gpus: usize) -> Calibration {
        Calibration {
            per_image,
            start_s: 4.0,
            workers,
            threads: 2,
            gpus,
        }
    }

    #[test]
    fn wall_is_start_plus_each_workers_share_of_images() {
        let c = cal(vec![10.0, 12.0, 8.0, 10.0], 2, 0);
        let (mean, se) = c.mean_and_se();
        assert!((mean - 10.0).abs() < 1e-9);
        // sample sd sqrt(8/3), se = sd / 2
        assert!((se - (8.0f64 / 3.0).sqrt() / 2.0).abs() < 1e-9, "{se}");
        let p = c.predict(101);
        assert_eq!(p.images_per_worker, 51);
        assert!((p.wall_s - (4.0 + 510.0)).abs() < 1e-9);
        assert!(p.range_s.0 < p.wall_s && p.wall_s < p.range_s.1);
        assert!((p.range_s.1 - p.wall_s - 51.0 * 2.0 * se).abs() < 1e-9);
        // 2 workers x 2 threads held for the whole wall time.
        assert!((p.held_hours - p.wall_s / 3600.0 * 4.0).abs() < 1e-12);
        assert!((p.per_hour - 101.0 / p.wall_s * 3600.0).abs() < 1e-9);
    }

    #[test]
    fn one_image_has_no_spread_and_gpus_count_gpu_hours() {
        let c = cal(vec![3.0], 4, 4);
        assert_eq!(c.mean_and_se(), (3.0, 0.0));
        let p = c.predict(8);
        assert_eq!(p.range_s, (p.wall_s, p.wall_s));
        assert!((p.held_hours - (4.0 + 6.0) / 3600.0 * 4.0).abs() < 1e-12);
    }

    #[test]
    fn children_cpu_is_read_from_proc() {
        let before = children_cpu_s().expect("/proc/self/stat");
        let st = std::process::Command::new("sh")
            .args(["-c", "i=0; while [ $i -lt 200000 ]; do i=$((i+1)); done"])
            .status()
            .unwrap();
        assert!(st.success());
        assert!(children_cpu_s().unwrap() > before);
    }
}
