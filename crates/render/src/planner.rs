//! The planner's model behind `clevrtex generate --estimate`: a few calibration images of the
//! run's own settings rendered by the pool into a scratch folder ([`calibrate`]), and the
//! prediction of a run's wall time, images/hour and core or GPU hours from them
//! ([`Calibration::predict`]), with a range from the calibration's spread.

use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::Mutex;

use crate::error::Result;
use crate::pool::{self, Job, Jobs, PoolEvent, PoolOptions, RunReport};

/// The fewest calibration images (`--calibrate`): one gives no spread, so a zero-width range.
pub const MIN_CALIBRATE: u32 = 2;
/// The most calibration images (`--calibrate`): more is a run, not a calibration.
pub const MAX_CALIBRATE: u32 = 100;

/// What the calibration measured.
#[derive(Debug, Clone, PartialEq)]
pub struct Calibration {
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
pub struct Prediction {
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

/// What [`calibrate`] made: the calibration (`None` when no image could be made) and what
/// the command prints of it.
pub struct Calibrated {
    /// The model's inputs; `None` when every calibration image failed.
    pub calibration: Option<Calibration>,
    /// The pool's report of the calibration run.
    pub report: RunReport,
    /// Calibration images that failed.
    pub failed: u64,
    /// The first failure's message.
    pub first_error: Option<String>,
    /// CPU seconds of the workers (Blender's, start included), where `/proc` tells.
    pub cpu_s: Option<f64>,
    /// The 1-minute load average before and after.
    pub load: (String, String),
}

/// Render `k` of `jobs`, spread over them, with the pool options `opts` (whose output folder
/// is a scratch folder: `--out` is never written); `on_line` gets a progress line per image.
pub fn calibrate(
    opts: &PoolOptions,
    jobs: &Jobs,
    k: usize,
    on_line: &(dyn Fn(String) + Sync),
) -> Result<Calibrated> {
    let jobs = spread(jobs, k);
    let k = jobs.len();
    let per_image = Mutex::new(Vec::new());
    let (ended, failed) = (AtomicU64::new(0), AtomicU64::new(0));
    let first_error = Mutex::new(None::<String>);
    let on_event = |ev: &PoolEvent| match ev {
        PoolEvent::Done { sample } => {
            let s = sample.visibility_s + sample.reject_s + sample.final_request_s + sample.post_s;
            per_image.lock().unwrap_or_else(|e| e.into_inner()).push(s);
            let e = ended.fetch_add(1, Ordering::Relaxed) + 1;
            on_line(format!("calibration: {e}/{k} images ({s:.1} s)"));
        }
        PoolEvent::Failed { index, error } => {
            failed.fetch_add(1, Ordering::Relaxed);
            let e = ended.fetch_add(1, Ordering::Relaxed) + 1;
            on_line(format!(
                "calibration: {e}/{k} images (image {index} failed: {error})"
            ));
            first_error
                .lock()
                .unwrap_or_else(|e| e.into_inner())
                .get_or_insert_with(|| error.to_string());
        }
        _ => {}
    };
    let cpu_before = children_cpu_s();
    let load_before = load_average();
    let report = pool::run(opts, Jobs::from(jobs), &on_event)?;
    let cpu_s = cpu_before.zip(children_cpu_s()).map(|(a, b)| b - a);
    let per_image = per_image.into_inner().unwrap_or_else(|e| e.into_inner());
    let calibration = (!per_image.is_empty()).then(|| Calibration {
        per_image,
        start_s: report.blender_start_s / report.worker_starts.max(1) as f64,
        workers: report.workers,
        threads: report.threads,
        gpus: opts.devices.iter().filter(|d| d.is_gpu()).count(),
    });
    Ok(Calibrated {
        calibration,
        report,
        failed: failed.load(Ordering::Relaxed),
        first_error: first_error.into_inner().unwrap_or_else(|e| e.into_inner()),
        cpu_s,
        load: (load_before, load_average()),
    })
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
