//! A pool of Blender workers rendering a list of jobs into the dataset layout.
//!
//! Per job: sample the scene (attempt 0), render the cheap visibility pass, count each
//! object's pixels and, if one is at or under the threshold, resample with the next attempt
//! number (deterministic: the attempt goes into the seed) before paying for the full render.
//! The final mask confirms the counts. A crashed, hung or babbling worker is killed and
//! restarted, and the request retried up to `retries` times; then the job is written to the
//! failure ledger and the run goes on (or stops, with `fail_fast`).

use std::collections::VecDeque;
use std::io::Write;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use clevrtex_scene::{Pass, SceneFile};

use crate::bridge::BridgeDir;
use crate::error::{RenderError, Result};
use crate::exr_io::Channels;
use crate::metadata::{self, RenderFacts};
use crate::output::{self, Staged};
use crate::post::{self, ObjectPixels, PngKind};
use crate::worker::{Mode, RenderReply, Worker, WorkerOptions};

/// Makes the scene of a job for a given attempt number.
pub type SceneMaker = Arc<dyn Fn(u32) -> std::result::Result<SceneFile, String> + Send + Sync>;

/// One image to produce.
#[derive(Clone)]
pub struct Job {
    /// Image index (the number in the stem).
    pub index: u64,
    /// Variant name (the output folder `clevrtex_<variant>`).
    pub variant: String,
    /// File stem, e.g. `CLEVRTEX_camo_000012`.
    pub stem: String,
    /// Passes written for this job (the scene file's `passes` are replaced by these, plus
    /// `mask`, which visibility needs; the mask file is written only when asked for).
    pub passes: Vec<Pass>,
    /// Produces the scene for attempt `n`.
    pub scene: SceneMaker,
    /// Whether a failed visibility check may resample (false for fixed scene files, whose
    /// visibility is only measured and recorded).
    pub resample: bool,
}

impl std::fmt::Debug for Job {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Job")
            .field("index", &self.index)
            .field("stem", &self.stem)
            .finish_non_exhaustive()
    }
}

/// How a run behaves.
#[derive(Debug, Clone)]
pub struct PoolOptions {
    /// The Blender executable.
    pub blender: PathBuf,
    /// Resolved material catalogue for the bridge.
    pub materials_json: String,
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
    /// The failure ledger (JSON lines, appended).
    pub ledger: PathBuf,
    /// Set by a Ctrl-C handler: stop at once, keep finished samples, leave no partial one.
    pub interrupt: Arc<AtomicBool>,
}

/// Without `--timeout`, a worker that prints nothing at all for this long is hung (Cycles
/// prints a line per sample; scene builds print too).
pub const IDLE_TIMEOUT: Duration = Duration::from_secs(300);

/// A generous per-request time limit for a scene: 10 minutes plus 8 s per sample at
/// 320x240 (about 15x what one CPU thread needs, so a crowded machine does not trip it),
/// doubled for the shadow pass's extra render. Hangs are caught sooner by [`IDLE_TIMEOUT`].
pub fn auto_timeout(scene: &SceneFile) -> Duration {
    let pixels = scene.render.width as f64 * scene.render.height as f64 / (320.0 * 240.0);
    let mut secs = 600.0 + 8.0 * scene.render.samples as f64 * pixels.max(0.05);
    if scene.passes.contains(&Pass::Shadow) {
        secs *= 2.0;
    }
    Duration::from_secs_f64(secs)
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
}

/// What one finished sample cost.
#[derive(Debug, Clone, Default)]
pub struct SampleStats {
    /// Image index.
    pub index: u64,
    /// Accepted attempt.
    pub attempt: u32,
    /// Where the metadata file went.
    pub metadata: PathBuf,
    /// Scene build time (bridge), accepted attempt.
    pub build_s: f64,
    /// Visibility pass time (whole request), accepted attempt.
    pub visibility_s: f64,
    /// Of all visibility passes of this image (accepted and rejected): the bridge's
    /// scene-build time and Cycles time.
    pub visibility_build_s: f64,
    /// See [`SampleStats::visibility_build_s`].
    pub visibility_render_s: f64,
    /// Cycles render time of the final render (including the no-shadow render).
    pub render_s: f64,
    /// Whole final request, as seen from Rust.
    pub final_request_s: f64,
    /// Rust post-processing and writing.
    pub post_s: f64,
    /// Rejected attempts of this image.
    pub rejects: u32,
    /// Visibility passes of this image (accepted and rejected).
    pub visibility_passes: u64,
    /// Wall time of the rejected attempts.
    pub reject_s: f64,
    /// Blender's projection of each object origin (`[x, y, depth]`).
    pub projected: Vec<[f64; 3]>,
    /// Per-object visibility in the final mask.
    pub objects: Vec<ObjectPixels>,
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
    /// Total Cycles time of final renders.
    pub render_s: f64,
    /// Total final-request time (build + render + bridge writing), accepted attempts.
    pub final_request_s: f64,
    /// Total post-processing time.
    pub post_s: f64,
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
}

impl RunReport {
    fn add(&mut self, s: &SampleStats) {
        self.done += 1;
        self.rejects += s.rejects as u64;
        self.build_s += s.build_s;
        self.visibility_s += s.visibility_s;
        self.visibility_build_s += s.visibility_build_s;
        self.visibility_render_s += s.visibility_render_s;
        self.visibility_passes += s.visibility_passes;
        self.render_s += s.render_s;
        self.final_request_s += s.final_request_s;
        self.post_s += s.post_s;
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
    bridge: BridgeDir,
    queue: Mutex<VecDeque<Job>>,
    report: Mutex<RunReport>,
    stop: AtomicBool,
    fatal: Mutex<Option<RenderError>>,
    ever_started: AtomicBool,
    threads: u32,
    ledger: Mutex<()>,
    on_event: &'a (dyn Fn(&PoolEvent) + Sync),
}

/// Render every job with `opts.workers` workers. Complete samples are skipped unless
/// `overwrite`. Returns the totals; a fatal error (Blender missing, output unwritable, or a
/// failed job with `fail_fast`) is returned as `Err` after the other workers stopped, and
/// an interrupt as [`RenderError::Interrupted`].
pub fn run(
    opts: &PoolOptions,
    jobs: Vec<Job>,
    on_event: &(dyn Fn(&PoolEvent) + Sync),
) -> Result<RunReport> {
    let started = Instant::now();
    let stems: std::collections::BTreeSet<String> = jobs.iter().map(|j| j.stem.clone()).collect();
    let bridge = BridgeDir::create(&opts.materials_json)?;
    let mut todo = VecDeque::new();
    let mut report = RunReport {
        workers: opts.workers.max(1),
        ..RunReport::default()
    };
    let mut cleaned = std::collections::BTreeSet::new();
    for job in jobs {
        let dir = output::sample_dir(&opts.out, &job.variant, job.index);
        if cleaned.insert(dir.clone()) {
            output::remove_stale_temps(&dir);
        }
        if !opts.overwrite && output::is_complete(&dir, &job.stem, &job.passes, opts.keep_exr) {
            report.skipped += 1;
            on_event(&PoolEvent::Skipped { index: job.index });
        } else {
            todo.push_back(job);
        }
    }
    let n_workers = opts.workers.max(1).min(todo.len().max(1));
    let shared = Shared {
        opts,
        bridge,
        queue: Mutex::new(todo),
        report: Mutex::new(report),
        stop: AtomicBool::new(false),
        fatal: Mutex::new(None),
        ever_started: AtomicBool::new(false),
        threads: if opts.threads > 0 {
            opts.threads
        } else {
            (available_cores() / n_workers).max(1) as u32
        },
        ledger: Mutex::new(()),
        on_event,
    };
    std::thread::scope(|s| {
        for _ in 0..n_workers {
            s.spawn(|| worker_thread(&shared));
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
    prune_ledger(&opts.ledger, &stems, &report)?;
    Ok(report)
}

/// After a finished run, drop the ledger entries of this run's samples that are complete
/// now (a rerun retried them), so the ledger lists only what is still missing; remove it
/// when nothing is.
fn prune_ledger(
    ledger: &Path,
    stems: &std::collections::BTreeSet<String>,
    report: &RunReport,
) -> Result<()> {
    let Ok(text) = std::fs::read_to_string(ledger) else {
        return Ok(());
    };
    let failed: std::collections::BTreeSet<u64> = report.failed.iter().map(|f| f.0).collect();
    let keep: Vec<&str> = text
        .lines()
        .filter(|line| {
            let Ok(v) = serde_json::from_str::<serde_json::Value>(line) else {
                return true;
            };
            let ran = v["stem"].as_str().is_some_and(|s| stems.contains(s));
            let failed_now = v["index"].as_u64().is_some_and(|i| failed.contains(&i));
            !ran || failed_now
        })
        .collect();
    if keep.len() == text.lines().count() {
        return Ok(());
    }
    if keep.is_empty() {
        return std::fs::remove_file(ledger).map_err(|e| RenderError::write(ledger, e));
    }
    let tmp = ledger.with_extension(format!("jsonl{}", output::TMP_SUFFIX));
    let body: String = keep.iter().map(|l| format!("{l}\n")).collect();
    std::fs::write(&tmp, body).map_err(|e| RenderError::write(&tmp, e))?;
    std::fs::rename(&tmp, ledger).map_err(|e| RenderError::write(ledger, e))
}

impl Shared<'_> {
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
        let _guard = self.ledger.lock().unwrap();
        let line = serde_json::json!({
            "index": job.index,
            "stem": job.stem,
            "variant": job.variant,
            "error": err.to_string(),
            "time_unix": std::time::SystemTime::now()
                .duration_since(std::time::UNIX_EPOCH)
                .map(|d| d.as_secs())
                .unwrap_or(0),
        });
        if let Some(parent) = self.opts.ledger.parent() {
            std::fs::create_dir_all(parent).map_err(|e| RenderError::write(parent, e))?;
        }
        let mut f = std::fs::OpenOptions::new()
            .create(true)
            .append(true)
            .open(&self.opts.ledger)
            .map_err(|e| RenderError::write(&self.opts.ledger, e))?;
        writeln!(f, "{line}").map_err(|e| RenderError::write(&self.opts.ledger, e))
    }
}

/// One worker slot: a (re)startable Blender process and its scratch folder.
struct Slot<'s, 'a> {
    shared: &'s Shared<'a>,
    worker: Option<Worker>,
    scratch: tempfile::TempDir,
}

fn worker_thread(shared: &Shared) {
    let scratch = match tempfile::Builder::new().prefix("clevrtex-work-").tempdir() {
        Ok(d) => d,
        Err(e) => {
            shared.set_fatal(RenderError::io(
                "cannot create a temporary folder in",
                std::env::temp_dir(),
                e,
                "set `TMPDIR` to a writable folder with free space",
            ));
            return;
        }
    };
    let mut slot = Slot {
        shared,
        worker: None,
        scratch,
    };
    loop {
        if shared.stopping() {
            break;
        }
        let Some(job) = shared.queue.lock().unwrap().pop_front() else {
            break;
        };
        match slot.run_job(&job) {
            Ok(stats) => {
                shared.report.lock().unwrap().add(&stats);
                (shared.on_event)(&PoolEvent::Done { sample: &stats });
            }
            Err(RenderError::Interrupted) => break,
            Err(err) if is_fatal(&err) => {
                shared.set_fatal(err);
                break;
            }
            Err(err) => {
                (shared.on_event)(&PoolEvent::Failed {
                    index: job.index,
                    error: &err,
                });
                if let Err(ledger_err) = shared.record_failure(&job, &err) {
                    shared.set_fatal(ledger_err);
                    break;
                }
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
    if let Some(w) = slot.worker.take() {
        if shared.opts.interrupt.load(Ordering::SeqCst) {
            drop(w); // kills
        } else {
            w.quit();
        }
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

/// Errors that stop the whole run: no Blender, or output that cannot be written.
fn is_fatal(err: &RenderError) -> bool {
    matches!(
        err,
        RenderError::BlenderNotFound { .. }
            | RenderError::Spawn { .. }
            | RenderError::WorkerStart(_)
            | RenderError::Io { .. }
    )
}

impl Slot<'_, '_> {
    fn opts(&self) -> &PoolOptions {
        self.shared.opts
    }

    /// A running worker, starting one if needed.
    fn worker(&mut self) -> Result<&mut Worker> {
        if self.worker.as_ref().is_some_and(|w| w.is_dead()) {
            self.worker = None;
        }
        if self.worker.is_none() {
            let opts = self.opts();
            let w = Worker::start(&WorkerOptions {
                blender: opts.blender.clone(),
                script: self.shared.bridge.worker_script(),
                materials: self.shared.bridge.materials_json(),
                threads: self.shared.threads,
                startup_timeout: opts.startup_timeout,
                interrupt: Arc::clone(&opts.interrupt),
            });
            let w = match w {
                Ok(w) => w,
                // A worker that never once started (wrong program, broken install) would fail
                // every job the same way: stop the run instead of filling the ledger.
                Err(e) if !self.shared.ever_started.load(Ordering::SeqCst) => {
                    return Err(RenderError::WorkerStart(Box::new(e)))
                }
                Err(e) => return Err(e),
            };
            let mut w = w;
            // With an explicit `--timeout` that limit is the only one; otherwise silence
            // for IDLE_TIMEOUT also counts as a hang.
            w.set_idle_timeout(opts.timeout.is_none().then_some(IDLE_TIMEOUT));
            self.shared.ever_started.store(true, Ordering::SeqCst);
            {
                let mut r = self.shared.report.lock().unwrap();
                r.worker_starts += 1;
                r.blender_start_s += w.startup_time().as_secs_f64();
            }
            (self.shared.on_event)(&PoolEvent::WorkerStarted {
                took: w.startup_time(),
            });
            self.worker = Some(w);
        }
        Ok(self.worker.as_mut().expect("just started"))
    }

    /// One request with restarts: a crash, hang or garbage kills the worker; a fresh one
    /// retries, up to `retries` times.
    fn request(
        &mut self,
        label: &str,
        scene: &Path,
        mode: Mode,
        dir: &Path,
        timeout: Duration,
    ) -> Result<RenderReply> {
        let mut tries = 0;
        loop {
            let result = self
                .worker()
                .and_then(|w| w.render_labelled(label, scene, mode, dir, timeout));
            match result {
                Err(e) if e.is_worker_failure() && tries < self.opts().retries => {
                    tries += 1;
                    self.worker = None;
                    (self.shared.on_event)(&PoolEvent::WorkerRestarted { error: &e });
                    if self.shared.stopping() {
                        return Err(RenderError::Interrupted);
                    }
                }
                Err(e) => {
                    if e.is_worker_failure() {
                        self.worker = None;
                    }
                    return Err(e);
                }
                Ok(r) => return Ok(r),
            }
        }
    }

    fn run_job(&mut self, job: &Job) -> Result<SampleStats> {
        let mut stats = SampleStats {
            index: job.index,
            ..SampleStats::default()
        };
        let opts = self.opts().clone();
        let attempts = if job.resample {
            opts.max_attempts.max(1)
        } else {
            1
        };
        let mut threshold = 0;
        for attempt in 0..attempts {
            if self.shared.stopping() {
                return Err(RenderError::Interrupted);
            }
            let t_attempt = Instant::now();
            let mut scene = (job.scene)(attempt).map_err(|message| RenderError::Sample {
                index: job.index,
                attempt,
                message,
            })?;
            // The bridge always renders the object-index pass: visibility and the metadata's
            // per-object pixel counts need it. Only requested passes become files.
            let mut bridge_passes = job.passes.clone();
            if !bridge_passes.contains(&Pass::Mask) {
                bridge_passes.push(Pass::Mask);
            }
            bridge_passes.sort();
            scene.passes = bridge_passes;
            threshold = post::visibility_threshold(scene.render.width, scene.render.height);
            let work = self.scratch.path().join(format!("{}-{attempt}", job.stem));
            let _ = std::fs::remove_dir_all(&work);
            std::fs::create_dir_all(&work).map_err(|e| RenderError::write(&work, e))?;
            let scene_path = work.join("scene.json");
            let text = serde_json::to_string_pretty(&scene).expect("scene serialises");
            post::write_file(&scene_path, text.as_bytes())?;
            let timeout = opts.timeout.unwrap_or_else(|| auto_timeout(&scene));
            let n = scene.objects.len();
            let label = format!("{} attempt {attempt}", job.stem);

            let mut visibility_s = 0.0;
            if job.resample && opts.visibility_check {
                let t = Instant::now();
                let reply = self.request(&label, &scene_path, Mode::Visibility, &work, timeout)?;
                stats.visibility_build_s += reply.timings.build_s;
                stats.visibility_render_s += reply.timings.render_s;
                stats.visibility_passes += 1;
                let exr = reply_file(&reply, "visibility", &work)?;
                let ch = Channels::read(&exr)?;
                let ids = post::instance_ids(ch.get("ViewLayer.IndexOB.X")?, n, &exr)?;
                let px = post::object_pixels(&ids, ch.width, n);
                visibility_s = t.elapsed().as_secs_f64();
                if px.iter().any(|p| p.pixels <= threshold) {
                    self.reject(job, attempt, t_attempt, &mut stats, &work);
                    continue;
                }
            }

            let t = Instant::now();
            let reply = self.request(&label, &scene_path, Mode::Final, &work, timeout)?;
            let final_request_s = t.elapsed().as_secs_f64();
            let t_post = Instant::now();
            let facts_blender = self
                .worker
                .as_ref()
                .map(|w| w.ready().blender_version.clone())
                .unwrap_or_default();
            let dir = output::sample_dir(&opts.out, &job.variant, job.index);
            let mut staged = Staged::new(&dir)?;
            let objects = write_passes(
                &reply,
                &work,
                &scene,
                &job.passes,
                &job.stem,
                opts.keep_exr,
                &mut staged,
            )?;
            if job.resample && objects.iter().any(|p| p.pixels <= threshold) {
                // The final mask disagrees with the cheap pass (e.g. displacement hides an
                // object): reject this layout too.
                drop(staged);
                self.reject(job, attempt, t_attempt, &mut stats, &work);
                continue;
            }
            let mut meta_scene = scene.clone();
            meta_scene.passes = job.passes.clone();
            let doc = metadata::build(
                &meta_scene,
                &RenderFacts {
                    objects: objects.clone(),
                    blender_version: facts_blender,
                    passes: job.passes.clone(),
                },
            );
            let meta_name = output::metadata_file(&job.stem);
            let text = serde_json::to_string_pretty(&doc).expect("metadata serialises");
            staged.write(&meta_name, text.as_bytes())?;
            // The last check before the point of no return: an interrupt now drops the staged
            // files, so no partial sample is left.
            if opts.interrupt.load(Ordering::SeqCst) {
                return Err(RenderError::Interrupted);
            }
            staged.commit()?;
            output::remove_other_outputs(&dir, &job.stem, &job.passes, opts.keep_exr);
            let _ = std::fs::remove_dir_all(&work);
            stats.attempt = attempt;
            stats.metadata = dir.join(meta_name);
            stats.build_s = reply.timings.build_s;
            stats.visibility_s = visibility_s;
            stats.render_s = reply.timings.render_s + reply.timings.noshadow_render_s;
            stats.final_request_s = final_request_s;
            stats.post_s = t_post.elapsed().as_secs_f64();
            stats.projected = reply.projected.clone();
            stats.objects = objects;
            return Ok(stats);
        }
        Err(RenderError::TooManyRejects {
            index: job.index,
            attempts,
            threshold,
        })
    }

    fn reject(
        &self,
        job: &Job,
        attempt: u32,
        since: Instant,
        stats: &mut SampleStats,
        work: &Path,
    ) {
        let cost = since.elapsed();
        stats.rejects += 1;
        stats.reject_s += cost.as_secs_f64();
        let _ = std::fs::remove_dir_all(work);
        (self.shared.on_event)(&PoolEvent::Rejected {
            index: job.index,
            attempt,
            cost,
        });
    }
}

/// A file the bridge says it wrote, which must lie in our scratch folder.
fn reply_file(reply: &RenderReply, role: &str, work: &Path) -> Result<PathBuf> {
    let path = reply
        .files
        .get(role)
        .ok_or_else(|| RenderError::BadOutput {
            path: work.to_path_buf(),
            problem: format!(
                "the bridge reported no `{role}` file (got: {})",
                reply.files.keys().cloned().collect::<Vec<_>>().join(", ")
            ),
        })?;
    if !path.is_file() {
        return Err(RenderError::BadOutput {
            path: path.clone(),
            problem: format!("the `{role}` file the bridge reported does not exist"),
        });
    }
    Ok(path.clone())
}

/// Three planes of float samples (R, G, B).
type Rgb = [Vec<f32>; 3];

/// The direct light with and without object shadows, per RGB channel: diffuse + glossy
/// (weighted by the colours of the final render) when the bridge wrote the glossy channels,
/// else diffuse direct light alone.
fn shadow_inputs(fin: &Channels, ns: &Channels) -> Result<(Rgb, Rgb)> {
    let name = |pass: &str, c: &str| format!("ViewLayer.{pass}.{c}");
    let has_gloss = ["GlossDir", "GlossCol", "DiffCol"]
        .iter()
        .all(|p| fin.channels.contains_key(&name(p, "R")))
        && ns.channels.contains_key(&name("GlossDir", "R"));
    let mut lit: Rgb = Default::default();
    let mut un: Rgb = Default::default();
    for (k, c) in ["R", "G", "B"].into_iter().enumerate() {
        if has_gloss {
            let (dc, gc) = (
                fin.get(&name("DiffCol", c))?,
                fin.get(&name("GlossCol", c))?,
            );
            lit[k] = post::direct_light(
                fin.get(&name("DiffDir", c))?,
                dc,
                fin.get(&name("GlossDir", c))?,
                gc,
            );
            un[k] = post::direct_light(
                ns.get(&name("DiffDir", c))?,
                dc,
                ns.get(&name("GlossDir", c))?,
                gc,
            );
        } else {
            lit[k] = fin.get(&name("DiffDir", c))?.to_vec();
            un[k] = ns.get(&name("DiffDir", c))?.to_vec();
        }
    }
    Ok((lit, un))
}

/// Decode the bridge's files, encode every requested pass into `staged`, and return the
/// per-object visibility measured on the final mask.
fn write_passes(
    reply: &RenderReply,
    work: &Path,
    scene: &SceneFile,
    passes: &[Pass],
    stem: &str,
    keep_exr: bool,
    staged: &mut Staged,
) -> Result<Vec<ObjectPixels>> {
    let exr_path = reply_file(reply, "passes", work)?;
    let ch = Channels::read(&exr_path)?;
    let (w, h) = (ch.width as u32, ch.height as u32);
    if (w, h) != (scene.render.width, scene.render.height) {
        return Err(RenderError::BadOutput {
            path: exr_path,
            problem: format!(
                "size {w}x{h} but the scene asks for {}x{}",
                scene.render.width, scene.render.height
            ),
        });
    }
    let n = scene.objects.len();
    let ids = post::instance_ids(ch.get("ViewLayer.IndexOB.X")?, n, &exr_path)?;
    let objects = post::object_pixels(&ids, ch.width, n);
    let png = |kind, d8: &[u8], d16: &[u16]| {
        post::encode_png(kind, w, h, d8, d16).map_err(|e| RenderError::BadOutput {
            path: exr_path.clone(),
            problem: format!("cannot encode PNG: {e}"),
        })
    };
    let rgb3 = |c: &Channels, base: &str, names: [&str; 3]| -> Result<[Vec<f32>; 3]> {
        Ok([
            c.get(&format!("{base}.{}", names[0]))?.to_vec(),
            c.get(&format!("{base}.{}", names[1]))?.to_vec(),
            c.get(&format!("{base}.{}", names[2]))?.to_vec(),
        ])
    };
    for &pass in passes {
        let name = output::pass_file(stem, pass);
        match pass {
            Pass::Rgb => staged.copy(&name, &reply_file(reply, "rgb", work)?)?,
            Pass::Mask => staged.write(&name, &png(PngKind::Palette8, &ids, &[])?)?,
            Pass::Depth => {
                let d = post::encode_depth(ch.get("ViewLayer.Depth.Z")?);
                staged.write(&name, &png(PngKind::Gray16, &[], &d)?)?
            }
            Pass::Normal => {
                let [x, y, z] = rgb3(&ch, "ViewLayer.Normal", ["X", "Y", "Z"])?;
                let d = post::encode_normal(&x, &y, &z);
                staged.write(&name, &png(PngKind::Rgb16, &[], &d)?)?
            }
            Pass::Albedo => {
                let [r, g, b] = rgb3(&ch, "ViewLayer.DiffCol", ["R", "G", "B"])?;
                staged.write(
                    &name,
                    &png(PngKind::Rgb8, &post::encode_albedo(&r, &g, &b), &[])?,
                )?
            }
            Pass::Shadow => {
                let ns_path = reply_file(reply, "noshadow", work)?;
                let ns = Channels::read(&ns_path)?;
                let (lit, un) = shadow_inputs(&ch, &ns)?;
                let s = post::encode_shadow([&lit[0], &lit[1], &lit[2]], [&un[0], &un[1], &un[2]]);
                staged.write(&name, &png(PngKind::Gray8, &s, &[])?)?
            }
        }
    }
    if keep_exr {
        let names = output::exr_files(stem, passes.contains(&Pass::Shadow));
        staged.copy(&names[0], &exr_path)?;
        if let Some(ns) = names.get(1) {
            staged.copy(ns, &reply_file(reply, "noshadow", work)?)?;
        }
    }
    Ok(objects)
}
