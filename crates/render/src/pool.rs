//! A pool of Blender workers rendering a list of jobs into the dataset layout.
//!
//! `N` threads each own a [`Slot`]: a [`Session`] (a restartable Blender worker) and a scratch
//! folder. They take jobs from one queue and run them (see [`crate::job`] for the attempt and
//! visibility policy of one job). A crashed, hung or babbling worker is killed and restarted,
//! and the request retried up to `retries` times; then the job is written to the failure
//! ledger ([`crate::ledger`]) and the run goes on (or stops, with `fail_fast`).

use std::collections::{BTreeSet, VecDeque};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use crate::bridge::BridgeDir;
use crate::error::{RenderError, Result};
use crate::job::{JobHost, JobSettings};
use crate::ledger::Ledger;
use crate::output;
use crate::session::{Hooks, Session};
use crate::worker::{RenderReply, Worker, WorkerOptions};
use clevrtex_dataset::layout;

pub use crate::job::{auto_timeout, Job, Jobs, SampleStats, SceneMaker};

/// How a run behaves.
#[derive(Debug, Clone)]
pub struct PoolOptions {
    /// The Blender executable.
    pub blender: PathBuf,
    /// Resolved material catalogue for the bridge.
    pub materials_json: String,
    /// The user materials (`--materials DIR`) a scene may use: name -> content hash of the
    /// `.blend` or file and every image it reads, recorded in each sample's metadata.
    pub user_materials: std::collections::BTreeMap<String, String>,
    /// The run's config hash (`generate`'s manifest `config_hash`), recorded in each sample's
    /// metadata; `None` (not recorded) for `render`.
    pub config_hash: Option<String>,
    /// Number of Blender processes.
    pub workers: usize,
    /// Cycles threads per process; 0 = the machine's cores shared evenly by the workers
    /// that actually run (never fewer than 1).
    pub threads: u32,
    /// Per-request time limit; `None` = [`auto_timeout`] of each scene.
    pub timeout: Option<Duration>,
    /// Time limit for a worker to start.
    pub startup_timeout: Duration,
    /// Restarts of a crashed/hung worker per request before the job fails.
    pub retries: u32,
    /// Layout attempts per image before giving up on it.
    pub max_attempts: u32,
    /// Run the cheap visibility pass before the full render.
    pub visibility_check: bool,
    /// Keep the float EXRs beside the PNGs.
    pub keep_exr: bool,
    /// Redo samples that are already complete.
    pub overwrite: bool,
    /// Stop at the first failed job.
    pub fail_fast: bool,
    /// Output root (`OUT` of `OUT/clevrtex_<variant>/...`).
    pub out: PathBuf,
    /// The failure ledger (JSON lines, one per failed image, rewritten atomically).
    pub ledger: PathBuf,
    /// Set by a Ctrl-C handler: stop at once, keep finished samples, leave no partial one.
    pub interrupt: Arc<AtomicBool>,
    /// The devices to spread the workers over, round robin ([`crate::device::plan`]); empty:
    /// the CPU.
    pub devices: Vec<crate::device::Placement>,
    /// When a worker is replaced between images.
    pub recycle: Recycle,
    /// A `generate` run's check of each sample it would skip as complete (`verify`'s check
    /// of one sample, against the manifests found before the run): one that fails is made
    /// again. `None` (`render`, `--overwrite`): every file present is complete.
    pub resume: Option<Arc<clevrtex_dataset::verify::ResumeCheck>>,
    /// Workers kept from an earlier run of this command, and kept for the next
    /// ([`crate::kept`]: a suite's variants); `None`: workers end with the run. With kept
    /// workers, the threads of `threads = 0` are the cores shared by `workers`, not by the
    /// workers this run's images need, so every run of the command starts its workers alike.
    pub keep: Option<Arc<crate::kept::KeptWorkers>>,
}

/// Without `--timeout`, a worker that prints nothing at all for this long is hung (Cycles
/// prints a line per sample; scene builds print too).
pub const IDLE_TIMEOUT: Duration = Duration::from_secs(300);

/// When a worker is replaced by a fresh one between two images (never during one): its
/// Blender's memory past a bound, or a number of images made.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct Recycle {
    /// Resident memory (bytes) past which a worker is recycled after its image
    /// (`--max-worker-memory`; `None`: never).
    pub max_rss: Option<u64>,
    /// Images after which a worker is recycled (`--recycle-after`; `None`: never).
    pub after_images: Option<u64>,
}

/// The default memory bound of one worker: half of this machine's memory shared by the
/// `workers`, at least 2 GiB (a 320x240 worker of the built-in materials holds well under
/// 1 GiB; docs/performance.md). `None` where the machine's memory is unknown.
pub fn default_max_rss(workers: usize) -> Option<u64> {
    let meminfo = std::fs::read_to_string("/proc/meminfo").ok()?;
    let kb: u64 = meminfo
        .lines()
        .find_map(|l| l.strip_prefix("MemTotal:"))?
        .trim()
        .trim_end_matches("kB")
        .trim()
        .parse()
        .ok()?;
    let share = kb.saturating_mul(1024) / 2 / workers.max(1) as u64;
    Some(share.max(2 << 30))
}

/// Progress reports, sent while the run goes.
#[derive(Debug)]
pub enum PoolEvent<'a> {
    /// A sample was already complete and was skipped.
    Skipped {
        /// Image index.
        index: u64,
    },
    /// A worker started.
    WorkerStarted {
        /// Start-up time.
        took: Duration,
    },
    /// A worker died and will be restarted.
    WorkerRestarted {
        /// Why.
        error: &'a RenderError,
    },
    /// A layout was rejected by the visibility check.
    Rejected {
        /// Image index.
        index: u64,
        /// Rejected attempt.
        attempt: u32,
        /// Wall time the attempt cost.
        cost: Duration,
    },
    /// A sample was written.
    Done {
        /// The sample.
        sample: &'a SampleStats,
    },
    /// A job failed and was written to the ledger.
    Failed {
        /// Image index.
        index: u64,
        /// Why.
        error: &'a RenderError,
    },
    /// A worker was let go between two images and the next image starts a fresh one.
    WorkerRecycled {
        /// Its Blender's resident memory then (bytes), where known.
        rss: Option<u64>,
        /// Images it made.
        images: u64,
        /// Why: `memory` (past `Recycle::max_rss`) or `images` (`Recycle::after_images`).
        why: &'static str,
    },
}

/// Totals of a run.
#[derive(Debug, Clone, Default)]
pub struct RunReport {
    /// Samples written.
    pub done: u64,
    /// Samples skipped because they were complete.
    pub skipped: u64,
    /// Jobs that failed (index, message).
    pub failed: Vec<(u64, String)>,
    /// Rejected layouts.
    pub rejects: u64,
    /// Workers started (including restarts).
    pub worker_starts: u64,
    /// Total worker start-up time.
    pub blender_start_s: f64,
    /// Total scene build time (accepted attempts).
    pub build_s: f64,
    /// Total visibility-pass time (accepted attempts).
    pub visibility_s: f64,
    /// Bridge scene-build time of all visibility passes (accepted and rejected).
    pub visibility_build_s: f64,
    /// Cycles time of all visibility passes (accepted and rejected).
    pub visibility_render_s: f64,
    /// Visibility passes run (accepted and rejected).
    pub visibility_passes: u64,
    /// Rejected layouts decided from the geometry, without a visibility pass (of `rejects`).
    pub prerejects: u64,
    /// Layouts accepted from the geometry, without a visibility pass.
    pub preaccepts: u64,
    /// Total Cycles time of final renders.
    pub render_s: f64,
    /// Total final-request time (build + render + bridge writing), accepted attempts.
    pub final_request_s: f64,
    /// Total post-processing time.
    pub post_s: f64,
    /// The bridge's phases of every request (accepted and rejected attempts).
    pub phases: crate::worker::BridgePhases,
    /// Total time of rejected attempts.
    pub reject_s: f64,
    /// Wall time of the run.
    pub wall_s: f64,
    /// Workers used.
    pub workers: usize,
    /// Cycles threads per worker.
    pub threads: u32,
    /// Whether the run was interrupted.
    pub interrupted: bool,
    /// Lines of the existing failure ledger that could not be read (dropped).
    pub ledger_unreadable: usize,
    /// The largest resident memory of a worker's Blender seen between two images (bytes; 0
    /// where unknown).
    pub peak_rss: u64,
    /// Workers recycled ([`Recycle`]).
    pub recycled: u64,
}

impl RunReport {
    /// Count a written sample.
    fn add(&mut self, s: &SampleStats) {
        self.done += 1;
        self.build_s += s.build_s;
        self.visibility_s += s.visibility_s;
        self.render_s += s.render_s;
        self.final_request_s += s.final_request_s;
        self.post_s += s.post_s;
        self.add_attempts(s);
    }

    /// Count what every image's attempts cost, written or failed: its rejected layouts,
    /// visibility passes and bridge phases (a failed image's rejects are in the split too).
    fn add_attempts(&mut self, s: &SampleStats) {
        self.rejects += s.rejects as u64;
        self.visibility_build_s += s.visibility_build_s;
        self.visibility_render_s += s.visibility_render_s;
        self.visibility_passes += s.visibility_passes;
        self.prerejects += u64::from(s.prerejects);
        self.preaccepts += u64::from(s.preaccepts);
        self.phases.add(&s.phases);
        self.reject_s += s.reject_s;
    }

    /// Worker-seconds spent per second of Cycles final rendering: `wall * workers /
    /// render_s`. 1.0 means no overhead at all; everything (start-up, builds, visibility
    /// passes, rejects, post-processing, idle workers) counts against it.
    pub fn overhead_ratio(&self) -> Option<f64> {
        (self.render_s > 0.0).then(|| self.wall_s * self.workers as f64 / self.render_s)
    }

    /// What the rejected attempts would have cost had visibility been checked only after
    /// the full render (the original generator): one mean full build + render per reject.
    pub fn rejects_cost_if_checked_after(&self) -> f64 {
        if self.done == 0 {
            return 0.0;
        }
        self.rejects as f64 * (self.final_request_s / self.done as f64)
    }
}

struct Shared<'a> {
    opts: &'a PoolOptions,
    bridge: Arc<BridgeDir>,
    jobs: Jobs,
    /// Runs of indices into `jobs` still to do, in order (one run for a fresh range: a
    /// resumed run of 100 million images holds a few ranges, not a list).
    queue: Mutex<VecDeque<std::ops::Range<u64>>>,
    report: Mutex<RunReport>,
    stop: AtomicBool,
    fatal: Mutex<Option<RenderError>>,
    /// Whether any worker of the run has started (see [`Session::sharing_start_flag`]).
    ever_started: Arc<AtomicBool>,
    threads: u32,
    ledger: Mutex<Ledger>,
    failed_stems: Mutex<BTreeSet<String>>,
    /// Sample folders already checked (not a link out of `--out`) and swept of dead runs'
    /// temporaries.
    swept: Mutex<std::collections::HashSet<PathBuf>>,
    on_event: &'a (dyn Fn(&PoolEvent) + Sync),
}

/// Render every job with `opts.workers` workers. Complete samples are skipped unless
/// `overwrite`. Returns the totals; a fatal error (Blender missing, output unwritable, or a
/// failed job with `fail_fast`) is returned as `Err` after the other workers stopped, and
/// an interrupt as [`RenderError::Interrupted`].
pub fn run(
    opts: &PoolOptions,
    jobs: impl Into<Jobs>,
    on_event: &(dyn Fn(&PoolEvent) + Sync),
) -> Result<RunReport> {
    let started = Instant::now();
    let jobs: Jobs = jobs.into();
    let bridge = match &opts.keep {
        Some(keep) => keep.bridge(&opts.materials_json)?,
        None => Arc::new(BridgeDir::create(&opts.materials_json)?),
    };
    let ledger = Ledger::open(&opts.ledger)?;
    let report = RunReport {
        workers: opts.workers.max(1),
        ledger_unreadable: ledger.unreadable(),
        ..RunReport::default()
    };
    // One lazy walk over the run's indices: a worker takes the next index, skips it when its
    // sample is complete, renders it otherwise. Nothing is done per index up front (a run of
    // 100 million images made 100,000 folders and checked as many files before its first
    // image, deaf to SIGTERM); folders are made when an image is written
    // (`output::Staged::new`).
    let mut todo: VecDeque<std::ops::Range<u64>> = VecDeque::new();
    if !jobs.is_empty() {
        todo.push_back(0..jobs.len());
    }
    let n_workers = opts
        .workers
        .max(1)
        .min(usize::try_from(jobs.len()).unwrap_or(usize::MAX).max(1));
    let shared = Shared {
        opts,
        bridge,
        jobs,
        queue: Mutex::new(todo),
        report: Mutex::new(report),
        stop: AtomicBool::new(false),
        fatal: Mutex::new(None),
        ever_started: Arc::new(AtomicBool::new(false)),
        threads: if opts.threads > 0 {
            opts.threads
        } else if opts.keep.is_some() {
            crate::device::default_threads(available_cores(), opts.workers.max(1))
        } else {
            crate::device::default_threads(available_cores(), n_workers)
        },
        ledger: Mutex::new(ledger),
        failed_stems: Mutex::new(BTreeSet::new()),
        swept: Mutex::new(std::collections::HashSet::new()),
        on_event,
    };
    std::thread::scope(|s| {
        for slot_index in 0..n_workers {
            let shared = &shared;
            s.spawn(move || worker_thread(shared, slot_index));
        }
    });
    let mut report = shared.report.into_inner().unwrap();
    report.workers = n_workers;
    report.threads = shared.threads;
    report.wall_s = started.elapsed().as_secs_f64();
    if let Some(err) = shared.fatal.into_inner().unwrap() {
        return Err(err);
    }
    if opts.interrupt.load(Ordering::SeqCst) {
        return Err(RenderError::Interrupted);
    }
    let failed = shared.failed_stems.into_inner().unwrap();
    let jobs = shared.jobs;
    shared
        .ledger
        .into_inner()
        .unwrap()
        .prune(&|s| jobs.has_stem(s), &failed)?;
    Ok(report)
}

impl Shared<'_> {
    /// Whether `job`'s sample is complete (to skip; never with `overwrite`). Its folder is
    /// looked at when one of its jobs is first taken: a folder that does not exist holds no
    /// complete sample (nothing is made here); one that does is refused when it is a link out
    /// of `--out` (a dataset handed over) before a file in it is read, and swept of
    /// temporaries that killed runs left.
    fn is_complete(&self, job: &Job) -> Result<bool> {
        let opts = self.opts;
        let dir = layout::sample_dir(&opts.out, &job.variant, job.index);
        let first = self.swept.lock().unwrap().insert(dir.clone());
        if std::fs::symlink_metadata(&dir).is_err() {
            // Not there yet: checked again when a later job of the folder is taken.
            self.swept.lock().unwrap().remove(&dir);
            return Ok(false);
        }
        if first {
            layout::make_dir(&opts.out, &dir).map_err(RenderError::Refused)?;
            output::remove_stale_temps(&dir);
        }
        Ok(!opts.overwrite
            && output::is_complete(&dir, &job.stem, &job.passes, opts.keep_exr)
            && opts
                .resume
                .as_ref()
                .is_none_or(|r| r.intact(job.index, &job.stem, &job.passes, opts.keep_exr)))
    }

    fn stopping(&self) -> bool {
        self.stop.load(Ordering::SeqCst) || self.opts.interrupt.load(Ordering::SeqCst)
    }

    fn set_fatal(&self, err: RenderError) {
        self.stop.store(true, Ordering::SeqCst);
        let mut f = self.fatal.lock().unwrap();
        if f.is_none() {
            *f = Some(err);
        }
    }

    fn record_failure(&self, job: &Job, err: &RenderError) -> Result<()> {
        let ledger = self.ledger.lock().unwrap();
        self.failed_stems.lock().unwrap().insert(job.stem.clone());
        ledger
            .record(job.index, &job.stem, &job.variant, err)
            .map_err(|cause| RenderError::LedgerWrite {
                path: ledger.path().to_path_buf(),
                index: job.index,
                failure: err.to_string(),
                cause,
            })
    }
}

/// One worker slot: a (re)startable Blender process and its scratch folder.
struct Slot<'s, 'a> {
    shared: &'s Shared<'a>,
    session: Session,
    scratch: tempfile::TempDir,
}

fn worker_thread(shared: &Shared, slot_index: usize) {
    let scratch = match crate::tmp::private_dir("clevrtex-work-") {
        Ok(d) => d,
        Err(e) => {
            shared.set_fatal(e);
            return;
        }
    };
    let opts = shared.opts;
    // With an explicit `--timeout` that limit is the only one; otherwise silence for
    // IDLE_TIMEOUT also counts as a hang, longer on a GPU whose kernel must be compiled first
    // (the driver says nothing meanwhile).
    let placement = crate::device::placement_for(&opts.devices, slot_index);
    let grace = if placement.compiles_kernel.is_some() {
        crate::device::KERNEL_COMPILE_GRACE
    } else {
        Duration::ZERO
    };
    let options = WorkerOptions::new(
        opts.blender.clone(),
        &shared.bridge,
        Arc::clone(&opts.interrupt),
    )
    .with_threads(shared.threads)
    .with_startup_timeout(opts.startup_timeout)
    .with_device(placement);
    let idle_timeout = opts.timeout.is_none().then_some(IDLE_TIMEOUT + grace);
    // (pid of the slot's worker, images it made since it started)
    let mut on_worker: (u32, u64) = (0, 0);
    let kept = opts.keep.as_ref().and_then(|k| k.take(&options));
    let session = match kept {
        Some((mut session, images)) => {
            // A live worker of an earlier run: a start failure from now on is one request's.
            session.set_policy(opts.retries, idle_timeout);
            shared.ever_started.store(true, Ordering::SeqCst);
            on_worker = images;
            session
        }
        None => Session::new(options, opts.retries, idle_timeout),
    }
    .sharing_start_flag(Arc::clone(&shared.ever_started));
    let mut slot = Slot {
        shared,
        session,
        scratch,
    };
    let settings = JobSettings {
        max_attempts: opts.max_attempts,
        visibility_check: opts.visibility_check,
        timeout: opts.timeout,
        out: opts.out.clone(),
        keep_exr: opts.keep_exr,
        grace,
        user_materials: opts.user_materials.clone(),
        config_hash: opts.config_hash.clone(),
    };
    loop {
        if shared.stopping() {
            break;
        }
        let next = {
            let mut queue = shared.queue.lock().unwrap();
            let next = queue.front_mut().map(|r| {
                r.start += 1;
                (r.start - 1, r.is_empty())
            });
            if let Some((_, true)) = next {
                queue.pop_front();
            }
            next.map(|(i, _)| i)
        };
        let Some(i) = next else {
            break;
        };
        let job = shared.jobs.get(i);
        match shared.is_complete(&job) {
            Ok(true) => {
                shared.report.lock().unwrap().skipped += 1;
                (shared.on_event)(&PoolEvent::Skipped { index: job.index });
                continue;
            }
            Ok(false) => {}
            Err(err) => {
                shared.set_fatal(err);
                break;
            }
        }
        let mut stats = SampleStats::default();
        let result = crate::job::run_job(&mut slot, &settings, &job, &mut stats);
        if result.is_err() {
            shared.report.lock().unwrap().add_attempts(&stats);
        }
        if !matches!(result, Err(RenderError::Interrupted)) && !shared.stopping() {
            recycle_between_images(&mut slot, &mut on_worker);
        }
        match result {
            Ok(()) => {
                shared.report.lock().unwrap().add(&stats);
                (shared.on_event)(&PoolEvent::Done { sample: &stats });
            }
            Err(RenderError::Interrupted) => break,
            Err(err) if is_fatal(&err) => {
                shared.set_fatal(err);
                break;
            }
            Err(err) => {
                // Record first: the event (and the CLI's "recorded in" message) only follows a
                // failure that really is in the ledger.
                if let Err(ledger_err) = shared.record_failure(&job, &err) {
                    shared.set_fatal(ledger_err);
                    break;
                }
                (shared.on_event)(&PoolEvent::Failed {
                    index: job.index,
                    error: &err,
                });
                shared
                    .report
                    .lock()
                    .unwrap()
                    .failed
                    .push((job.index, err.to_string()));
                if shared.opts.fail_fast {
                    shared.set_fatal(err);
                    break;
                }
            }
        }
    }
    // A live worker goes on to the command's next run, unless this run stops it.
    match &opts.keep {
        Some(keep) if !shared.stopping() => keep.put(slot.session, on_worker),
        _ => slot.session.close(),
    }
}

/// After an image (made or failed), between two requests: note the worker's memory, and let
/// it go (it quits; the next image starts a fresh one) when it is past the bound or has made
/// its number of images ([`Recycle`]). `on_worker`: the worker's pid and images made.
fn recycle_between_images(slot: &mut Slot, on_worker: &mut (u32, u64)) {
    let Some(w) = slot.session.current() else {
        *on_worker = (0, 0);
        return;
    };
    let pid = w.pid();
    if on_worker.0 != pid {
        *on_worker = (pid, 0);
    }
    on_worker.1 += 1;
    let rss = w.rss_bytes();
    let recycle = slot.shared.opts.recycle;
    let why = if rss.zip(recycle.max_rss).is_some_and(|(r, max)| r > max) {
        Some("memory")
    } else if recycle.after_images.is_some_and(|n| on_worker.1 >= n) {
        Some("images")
    } else {
        None
    };
    {
        let mut report = slot.shared.report.lock().unwrap();
        report.peak_rss = report.peak_rss.max(rss.unwrap_or(0));
        if why.is_some() {
            report.recycled += 1;
        }
    }
    if let Some(why) = why {
        (slot.shared.on_event)(&PoolEvent::WorkerRecycled {
            rss,
            images: on_worker.1,
            why,
        });
        slot.session.close();
        *on_worker = (0, 0);
    }
}

/// Logical cores of this machine (1 if unknown).
pub fn available_cores() -> usize {
    std::thread::available_parallelism()
        .map(|n| n.get())
        .unwrap_or(1)
}

/// Default number of workers: two when there are at least two cores, so one worker's
/// serial work (scene build, visibility pass, post-processing) overlaps the other's render;
/// more only pays on big machines (each Blender costs memory).
pub fn default_workers() -> usize {
    match available_cores() {
        0 | 1 => 1,
        n if n < 16 => 2,
        n => n / 8,
    }
}

/// Errors that stop the whole run: no Blender, or output that cannot (or will not) be written.
fn is_fatal(err: &RenderError) -> bool {
    matches!(
        err,
        RenderError::BlenderNotFound { .. }
            | RenderError::Spawn { .. }
            | RenderError::WorkerStart(_)
            | RenderError::Io(_)
            | RenderError::Refused(_)
    )
}

impl JobHost for Slot<'_, '_> {
    fn stopping(&self) -> bool {
        self.shared.stopping()
    }

    fn interrupted(&self) -> bool {
        self.shared.opts.interrupt.load(Ordering::SeqCst)
    }

    fn scratch(&self) -> &Path {
        self.scratch.path()
    }

    fn blender(
        &self,
    ) -> (
        String,
        std::collections::BTreeMap<String, serde_json::Value>,
    ) {
        self.session
            .current()
            .map(|w| (w.ready().blender_version.clone(), w.ready().compat.clone()))
            .unwrap_or_default()
    }

    fn rejected(&self, index: u64, attempt: u32, cost: Duration) {
        (self.shared.on_event)(&PoolEvent::Rejected {
            index,
            attempt,
            cost,
        });
    }

    /// Run `call` on the slot's worker, with restarts (see [`Session::request`]).
    fn request(
        &mut self,
        call: &mut dyn FnMut(&mut Worker) -> Result<RenderReply>,
    ) -> Result<RenderReply> {
        self.session.request(&mut PoolHooks(self.shared), call)
    }
}

/// A slot's session reports to the run: start counts and times, restart events, and the
/// run's stop flag.
struct PoolHooks<'s, 'a>(&'s Shared<'a>);

impl Hooks for PoolHooks<'_, '_> {
    fn started(&mut self, worker: &Worker) {
        {
            let mut r = self.0.report.lock().unwrap();
            r.worker_starts += 1;
            r.blender_start_s += worker.startup_time().as_secs_f64();
        }
        (self.0.on_event)(&PoolEvent::WorkerStarted {
            took: worker.startup_time(),
        });
    }

    fn restarting(&mut self, error: &RenderError) {
        (self.0.on_event)(&PoolEvent::WorkerRestarted { error });
    }

    fn stopping(&self) -> bool {
        self.0.stopping()
    }
}
