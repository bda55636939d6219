//! A batch of `generate` or `render` after its arguments are parsed: the pool's options
//! planned from the run's settings ([`plan`]: the user materials checked, the devices probed,
//! the workers chosen) and the pool run under the range's lock, its plan written first and
//! its manifest last ([`run`]). The command prints: it gets the pool's events, and the lines
//! to show, through its callbacks.

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};
use std::time::Duration;

use clevrtex_dataset::manifest;
use clevrtex_materials::Catalogue;

use crate::device::{self, DeviceChoice};
use crate::error::{RenderError, Result};
use crate::pool::{self, Jobs, PoolEvent, PoolOptions, RunReport};
use crate::user_materials::{self, Checked};

/// A run's settings, checked by the command (`generate`'s and `render`'s flags).
#[derive(Debug, Clone)]
pub struct Settings {
    /// The Blender found.
    pub blender: PathBuf,
    /// `--device`.
    pub device: DeviceChoice,
    /// `--workers` (`None`: by the devices and cores).
    pub workers: Option<usize>,
    /// `--threads` (`None`: Blender's choice).
    pub threads: Option<u32>,
    /// `--timeout` (`None`: by the render's size and samples).
    pub timeout: Option<Duration>,
    /// `--startup-timeout`.
    pub startup_timeout: Duration,
    /// `--retries`.
    pub retries: u32,
    /// `--keep-exr`.
    pub keep_exr: bool,
    /// `--overwrite`.
    pub overwrite: bool,
    /// `--fail-fast`.
    pub fail_fast: bool,
    /// `--out`.
    pub out: PathBuf,
    /// `--max-worker-memory` in bytes (`None`: [`pool::default_max_rss`]).
    pub max_worker_memory: Option<u64>,
    /// `--recycle-after` (`None`: never by count).
    pub recycle_after: Option<u64>,
    /// Workers kept between the runs of one command (`generate --suite`: one run per variant),
    /// and its device plan: [`crate::kept`]. `None`: this run's workers end with it.
    pub keep: Option<Arc<crate::kept::KeptWorkers>>,
}

/// The pool's options for a run and the user materials it checked (which must outlive the
/// run: Blender reads their copies), with the lines the command shows (devices, warnings).
pub struct Planned {
    /// The pool's options.
    pub opts: PoolOptions,
    /// The checked user materials.
    pub user: Checked,
    /// Lines for stderr: the GPUs used, kernel and workers-per-GPU warnings.
    pub notes: Vec<String>,
}

/// `--max-worker-memory GIB` in bytes: more than 0 and at most a million GiB.
pub fn memory_bound(gib: Option<f64>) -> std::result::Result<Option<u64>, String> {
    match gib {
        Some(g) if !(g > 0.0 && g <= 1e6) => Err(format!(
            "`--max-worker-memory {g}` is out of range\nhint: pass the GiB a worker may hold, more than 0 (e.g. 8)"
        )),
        Some(g) => Ok(Some((g * (1u64 << 30) as f64) as u64)),
        None => Ok(None),
    }
}

/// Plan the pool for `settings`: the user materials of `catalogue` that `used` names checked
/// (and `catalogue` pointed at their copies), the devices planned (a first worker asked for
/// its GPUs where `--device` needs them), the workers and threads; failures to `ledger`;
/// `interrupt` stops it.
pub fn plan(
    s: &Settings,
    ledger: PathBuf,
    max_attempts: u32,
    interrupt: &Arc<AtomicBool>,
    (catalogue, used): (&mut Catalogue, &BTreeSet<String>),
) -> Result<Planned> {
    let user = user_materials::check_before_run(
        catalogue,
        used,
        &s.blender,
        s.startup_timeout,
        Arc::clone(interrupt),
    )?;
    let materials_json = catalogue.resolved_json();
    let probe = || {
        crate::gpu_probe::plan_devices(
            s.device,
            &s.blender,
            &materials_json,
            s.startup_timeout,
            interrupt,
        )
    };
    let devices = match &s.keep {
        Some(keep) => keep.devices(s.device, &s.blender, probe)?,
        None => probe()?,
    };
    let mut notes = Vec::new();
    if devices.iter().any(|d| d.is_gpu()) {
        let names: Vec<String> = devices.iter().map(|d| d.describe()).collect();
        notes.push(format!("devices: {}", names.join(", ")));
    }
    let workers = s.workers.unwrap_or_else(|| {
        device::default_workers(&devices, pool::default_workers(), pool::available_cores())
    });
    notes.extend(
        [
            device::kernel_compile_warning(&devices),
            device::workers_per_gpu_warning(&devices, workers),
        ]
        .into_iter()
        .flatten(),
    );
    let opts = PoolOptions {
        blender: s.blender.clone(),
        materials_json,
        user_materials: user_materials::hashes(&user.entries),
        config_hash: None,
        workers,
        threads: s.threads.unwrap_or(0),
        timeout: s.timeout,
        startup_timeout: s.startup_timeout,
        retries: s.retries,
        max_attempts: max_attempts.max(1),
        visibility_check: true,
        keep_exr: s.keep_exr,
        overwrite: s.overwrite,
        fail_fast: s.fail_fast,
        out: s.out.clone(),
        ledger,
        interrupt: Arc::clone(interrupt),
        devices,
        recycle: pool::Recycle {
            max_rss: s
                .max_worker_memory
                .or_else(|| pool::default_max_rss(workers)),
            after_images: s.recycle_after,
        },
        resume: None,
        keep: s.keep.clone(),
    };
    Ok(Planned { opts, user, notes })
}

/// How a [`run`] ended.
pub enum Ended {
    /// The pool ran to its end (some images may have failed: `report.failed`).
    Finished {
        /// The pool's report.
        report: RunReport,
        /// The manifest written, when the run had a plan.
        manifest: Option<PathBuf>,
    },
    /// Ctrl-C or SIGTERM stopped it; finished samples are kept, no manifest was written.
    Interrupted {
        /// The pool's report, when the pool itself ended.
        report: Option<RunReport>,
    },
}

/// What the command hears of a run: the pool's events, and lines to show (a card that could
/// not be written).
pub struct Hooks<'a> {
    /// Each pool event, from the workers' threads.
    pub on_event: &'a (dyn Fn(&PoolEvent) + Sync),
    /// A warning line for stderr.
    pub warn: &'a (dyn Fn(String) + Sync),
}

/// Render `jobs` with the pool options of `planned`. With `plan` (a dataset's run): under the
/// range's lock (a run overlapping a live one is refused before anything is written), the
/// folder's settings checked, the plan written first and the manifest of what was made last,
/// the user materials and config hash recorded, and the dataset card rewritten at both ends.
/// `command` is this process's command line, recorded in the lock.
pub fn run(
    planned: &mut Planned,
    jobs: Jobs,
    mut plan: Option<manifest::Plan>,
    command: Vec<String>,
    hooks: &Hooks,
) -> std::result::Result<Ended, RunError> {
    let out = planned.opts.out.clone();
    if let Some(plan) = plan.as_mut() {
        plan.run.user_materials = planned.user.entries.clone();
        // Each sample records the run's config hash, so `verify` can tell a sample made from
        // another config than the manifest claiming it.
        planned.opts.config_hash = Some(plan.run.config_hash.clone());
    }
    // Seconds per finished sample, by index, for the manifest (`clevrtex report` plots them).
    let seconds = Mutex::new(BTreeMap::<u64, f64>::new());
    let on_event = |ev: &PoolEvent| {
        if let PoolEvent::Done { sample } = ev {
            let s = sample.visibility_s + sample.reject_s + sample.final_request_s + sample.post_s;
            seconds
                .lock()
                .unwrap_or_else(|e| e.into_inner())
                .insert(sample.index, s);
        }
        (hooks.on_event)(ev);
    };
    let card = |out: &Path| {
        if let Err(e) = clevrtex_dataset::card::write_card(out) {
            (hooks.warn)(format!("warning: the dataset card was not written: {e}"));
        }
    };
    // One writer per range: a run whose indices overlap a live run's refuses here, before
    // anything is written; then the plan, so even a run that never ends is known to `verify`.
    let mut resume = None;
    let _lock = match &plan {
        Some(p) => {
            let lock = clevrtex_dataset::run_lock::RunLock::acquire(
                &p.variant_dir(&out),
                p.run.start,
                p.run.end,
                p.run.shard,
                command,
            )
            .map_err(RunError::Refused)?;
            // The lock made the variant folder (`layout::make_dir`: not a link out of `--out`).
            // Under the lock, before anything is written: a folder of a run with other
            // settings is refused.
            p.check_settings(&out, planned.opts.overwrite)?;
            // What a killed commit left beside the manifests and the card (the sample
            // folders are swept as their jobs start).
            clevrtex_dataset::atomic::remove_stale_temps(&p.variant_dir(&out));
            clevrtex_dataset::atomic::remove_stale_temps(&out);
            // A sample is skipped as complete only when it passes `verify`'s check against
            // the manifests as they are before this run's plan replaces its own.
            if !planned.opts.overwrite {
                resume = Some(Arc::new(clevrtex_dataset::verify::ResumeCheck::new(
                    &out,
                    &p.run.variant,
                )));
            }
            p.write_plan(&out)?;
            card(&out);
            Some(lock)
        }
        None => None,
    };
    planned.opts.resume = resume.clone();
    let opts = &planned.opts;
    let report = match pool::run(opts, jobs, &on_event) {
        Ok(r) => r,
        Err(RenderError::Interrupted) => return Ok(Ended::Interrupted { report: None }),
        Err(e) => return Err(e.into()),
    };
    let Some(p) = plan else {
        return Ok(Ended::Finished {
            report,
            manifest: None,
        });
    };
    let seconds = seconds.into_inner().unwrap_or_else(|e| e.into_inner());
    let failed: BTreeSet<u64> = report.failed.iter().map(|(i, _)| *i).collect();
    if let Some(r) = &resume {
        let remade = r.remade();
        if !remade.is_empty() {
            (hooks.warn)(format!(
                "warning: {} sample(s) had every file but did not pass `clevrtex verify`'s check, so they were made again (a rerun never keeps what it cannot check):",
                remade.len()
            ));
            for line in remade.iter().take(10) {
                (hooks.warn)(format!("  {}", clevrtex_scene::text::printable(line)));
            }
        }
    }
    let checked = resume.as_ref().map(|r| r.checked());
    let path = match p.write(&out, &seconds, &failed, &opts.interrupt, checked.as_ref()) {
        Ok(path) => path,
        Err(_) if opts.interrupt.load(Ordering::SeqCst) => {
            return Ok(Ended::Interrupted {
                report: Some(report),
            })
        }
        Err(e) => return Err(e.into()),
    };
    card(&out);
    Ok(Ended::Finished {
        report,
        manifest: Some(path),
    })
}

/// Why a [`run`] stopped with nothing to show for it.
#[derive(Debug)]
pub enum RunError {
    /// A render error (Blender, the pool).
    Render(RenderError),
    /// The dataset refused (a live run's range, a folder of other settings, the manifest).
    Dataset(clevrtex_dataset::error::Error),
    /// The range's lock refused, with its message.
    Refused(String),
}

impl std::fmt::Display for RunError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            RunError::Render(e) => e.fmt(f),
            RunError::Dataset(e) => e.fmt(f),
            RunError::Refused(m) => f.write_str(m),
        }
    }
}

impl std::error::Error for RunError {}

impl From<RenderError> for RunError {
    fn from(e: RenderError) -> Self {
        RunError::Render(e)
    }
}

impl From<clevrtex_dataset::error::Error> for RunError {
    fn from(e: clevrtex_dataset::error::Error) -> Self {
        RunError::Dataset(e)
    }
}
