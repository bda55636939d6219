//! One job: the attempt and visibility policy that turns a [`Job`] into a written sample.
//!
//! Per job: sample the scene (attempt 0), render the cheap visibility pass, count each
//! object's pixels and, if one is at or under the threshold, resample with the next attempt
//! number (deterministic: the attempt goes into the seed) before paying for the full render.
//! The final mask confirms the counts.

use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::time::{Duration, Instant};

use clevrtex_dataset::layout;
use clevrtex_scene::{Pass, SceneFile};

use crate::error::{RenderError, Result};
use crate::exr_io::Channels;
use crate::metadata::{self, RenderFacts};
use crate::output::{self, Staged};
use crate::passes::write_passes;
use crate::post::{self, ObjectPixels};
use crate::worker::{Mode, RenderReply, Worker};

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
    /// The user's scene file this job renders (`clevrtex render`), named in messages instead
    /// of the worker's temporary copy.
    pub source: Option<PathBuf>,
}

/// Makes job `i` of a run.
type JobMaker = Arc<dyn Fn(u64) -> Job + Send + Sync>;
/// Whether a stem is one of a run's.
type StemTest = Arc<dyn Fn(&str) -> bool + Send + Sync>;

/// The jobs of a run, made one at a time as workers take them: a run of 100 million images
/// holds no list of them (a list of `generate -n 100000000`'s jobs took 12.8 GB up front).
/// A list of jobs (`render`'s scene files) converts with `From`.
#[derive(Clone)]
pub struct Jobs {
    len: u64,
    make: JobMaker,
    has_stem: StemTest,
}

impl Jobs {
    /// `len` jobs, job `i` made by `make(i)`; `has_stem` says whether a stem is one of them
    /// (the failure ledger keeps other runs' entries).
    pub fn lazy(
        len: u64,
        make: impl Fn(u64) -> Job + Send + Sync + 'static,
        has_stem: impl Fn(&str) -> bool + Send + Sync + 'static,
    ) -> Jobs {
        Jobs {
            len,
            make: Arc::new(make),
            has_stem: Arc::new(has_stem),
        }
    }

    /// Number of jobs.
    pub fn len(&self) -> u64 {
        self.len
    }

    /// Whether there are none.
    pub fn is_empty(&self) -> bool {
        self.len == 0
    }

    /// Job `i` (`i < len`).
    pub fn get(&self, i: u64) -> Job {
        (self.make)(i)
    }

    /// Whether `stem` is one of the run's jobs.
    pub fn has_stem(&self, stem: &str) -> bool {
        (self.has_stem)(stem)
    }
}

impl From<Vec<Job>> for Jobs {
    fn from(list: Vec<Job>) -> Jobs {
        let stems: std::collections::BTreeSet<String> =
            list.iter().map(|j| j.stem.clone()).collect();
        let list = Arc::new(list);
        Jobs::lazy(
            list.len() as u64,
            move |i| list[i as usize].clone(),
            move |s| stems.contains(s),
        )
    }
}

impl std::fmt::Debug for Job {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Job")
            .field("index", &self.index)
            .field("stem", &self.stem)
            .finish_non_exhaustive()
    }
}

/// A generous per-request time limit for a scene: 10 minutes plus 8 s per sample at
/// 320x240 (about 15x what one CPU thread needs, so a crowded machine does not trip it),
/// doubled for the shadow pass's extra renders. Hangs are caught sooner by [`IDLE_TIMEOUT`].
pub fn auto_timeout(scene: &SceneFile) -> Duration {
    let pixels = scene.render.width as f64 * scene.render.height as f64 / (320.0 * 240.0);
    let mut secs = 600.0 + 8.0 * scene.render.samples as f64 * pixels.max(0.05);
    if scene.passes.contains(&Pass::Shadow) {
        secs *= 2.0;
    }
    Duration::from_secs_f64(secs)
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
    /// Cycles render time of the final render (including the shadow pass's render).
    pub render_s: f64,
    /// Whole final request, as seen from Rust.
    pub final_request_s: f64,
    /// Rust post-processing and writing.
    pub post_s: f64,
    /// Rejected attempts of this image.
    pub rejects: u32,
    /// Visibility passes of this image (accepted and rejected).
    pub visibility_passes: u64,
    /// Rejected attempts of this image decided from the geometry alone
    /// ([`clevrtex_scene::visibility`]), without a visibility render (counted in `rejects`).
    pub prerejects: u32,
    /// Layouts accepted from the geometry alone, without a visibility render (at most one per
    /// image: the final mask may still reject it).
    pub preaccepts: u32,
    /// Wall time of the rejected attempts.
    pub reject_s: f64,
    /// The bridge's phases of every request of this image (visibility and final, accepted
    /// and rejected attempts).
    pub phases: crate::worker::BridgePhases,
    /// Blender's projection of each object origin (`[x, y, depth]`).
    pub projected: Vec<[f64; 3]>,
    /// Per-object visibility in the final mask.
    pub objects: Vec<ObjectPixels>,
}

/// What a job needs from the worker slot that runs it (the pool's slot: `pool.rs`).
pub(crate) trait JobHost {
    /// Whether the run is stopping (a fatal error elsewhere, or an interrupt).
    fn stopping(&self) -> bool;
    /// Whether the run was interrupted (Ctrl-C, SIGTERM).
    fn interrupted(&self) -> bool;
    /// The slot's scratch folder.
    fn scratch(&self) -> &Path;
    /// Run `call` on the slot's worker, with restarts (see [`crate::Session::request`]).
    fn request(
        &mut self,
        call: &mut dyn FnMut(&mut Worker) -> Result<RenderReply>,
    ) -> Result<RenderReply>;
    /// The Blender version of the slot's current worker and the bridge's version-parity
    /// settings on it (`ready.compat`; empty if none).
    fn blender(
        &self,
    ) -> (
        String,
        std::collections::BTreeMap<String, serde_json::Value>,
    );
    /// Tell the run that attempt `attempt` of image `index` was rejected after `cost`.
    fn rejected(&self, index: u64, attempt: u32, cost: Duration);
}

/// What a job needs of the run's options.
#[derive(Debug, Clone)]
pub(crate) struct JobSettings {
    /// Layout attempts per image before giving up on it.
    pub(crate) max_attempts: u32,
    /// Run the cheap visibility pass before the full render.
    pub(crate) visibility_check: bool,
    /// Per-request time limit; `None` = [`auto_timeout`] of each scene.
    pub(crate) timeout: Option<Duration>,
    /// Output root.
    pub(crate) out: PathBuf,
    /// Keep the float EXRs beside the PNGs.
    pub(crate) keep_exr: bool,
    /// Added to [`auto_timeout`] (not to an explicit `timeout`): [`KERNEL_COMPILE_GRACE`] on a
    /// GPU whose kernel the driver compiles first, else zero.
    ///
    /// [`KERNEL_COMPILE_GRACE`]: crate::device::KERNEL_COMPILE_GRACE
    pub(crate) grace: Duration,
    /// User material name -> content hash ([`crate::pool::PoolOptions::user_materials`]).
    pub(crate) user_materials: std::collections::BTreeMap<String, String>,
    /// The run's config hash ([`crate::pool::PoolOptions::config_hash`]).
    pub(crate) config_hash: Option<String>,
}

/// Turn `job` into a written sample on `slot`: attempts, the visibility check, the final
/// render, its passes and metadata, committed at once.
///
/// On failure, `stats` still holds what the image cost before it failed (its rejected
/// layouts, visibility passes and phases), for the run's time split.
pub(crate) fn run_job(
    slot: &mut dyn JobHost,
    opts: &JobSettings,
    job: &Job,
    stats: &mut SampleStats,
) -> Result<()> {
    *stats = SampleStats {
        index: job.index,
        ..SampleStats::default()
    };
    let attempts = if job.resample {
        opts.max_attempts.max(1)
    } else {
        1
    };
    let mut threshold = 0;
    let mut size = (0, 0);
    for attempt in 0..attempts {
        if slot.stopping() {
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
        size = (scene.render.width, scene.render.height);
        // The geometric pre-reject: an object whose upper bound of visible pixels is at or
        // under the threshold fails the visibility render for certain, so that render (and the
        // scene build) is skipped; the attempts and accepted layouts are the same.
        if job.resample && opts.visibility_check && prerejected(&scene, threshold) {
            stats.prerejects += 1;
            reject(slot, job, attempt, t_attempt, stats, Path::new(""));
            continue;
        }
        // The geometric pre-accept: every object's lower bound is over the threshold, so the
        // visibility render accepts for certain and is skipped; the final mask is checked as
        // always.
        let preaccepted = job.resample && opts.visibility_check && preaccepted(&scene, threshold);
        let work = slot.scratch().join(format!("{}-{attempt}", job.stem));
        let _ = std::fs::remove_dir_all(&work);
        std::fs::create_dir_all(&work).map_err(|e| RenderError::write(&work, e))?;
        let scene_path = work.join("scene.json");
        let text = serde_json::to_string_pretty(&scene).expect("scene serialises");
        post::write_file(&scene_path, text.as_bytes())?;
        let timeout = opts
            .timeout
            .unwrap_or_else(|| auto_timeout(&scene) + opts.grace);
        let n = scene.objects.len();
        let label = match &job.source {
            Some(file) => format!("{} (scene file `{}`)", job.stem, file.display()),
            None => format!("{} attempt {attempt}", job.stem),
        };

        let mut visibility_s = 0.0;
        if preaccepted {
            stats.preaccepts += 1;
        } else if job.resample && opts.visibility_check {
            let t = Instant::now();
            let reply = slot.request(&mut |w| {
                w.check_features(&scene.render)?;
                w.render_labelled(&label, &scene_path, Mode::Visibility, &work, timeout)
            })?;
            stats.phases.add(&reply.timings.phases);
            stats.visibility_build_s += reply.timings.build_s;
            stats.visibility_render_s += reply.timings.render_s;
            stats.visibility_passes += 1;
            let exr = reply.file("visibility", &work)?;
            // Bounded by its header (`Channels::read`), not held to the size asked for: Blender
            // renders at least 4x4, and a smaller image is blamed for its rejects below.
            let ch = Channels::read(&exr)?;
            let ids = post::instance_ids(ch.get(&crate::passes::index_channel())?, n, &exr)?;
            let px = post::object_pixels(&ids, ch.width, n);
            visibility_s = t.elapsed().as_secs_f64();
            if px.iter().any(|p| p.pixels <= threshold) {
                reject(slot, job, attempt, t_attempt, stats, &work);
                continue;
            }
        }

        let t = Instant::now();
        let reply = slot.request(&mut |w| {
            w.check_features(&scene.render)?;
            w.render_labelled(&label, &scene_path, Mode::Final, &work, timeout)
        })?;
        let final_request_s = t.elapsed().as_secs_f64();
        stats.phases.add(&reply.timings.phases);
        let t_post = Instant::now();
        let (facts_blender, facts_compat) = slot.blender();
        let dir = layout::sample_dir(&opts.out, &job.variant, job.index);
        let mut staged = Staged::new(&opts.out, &dir)?;
        let objects = write_passes(
            &|role| reply.file(role, &work),
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
            reject(slot, job, attempt, t_attempt, stats, &work);
            continue;
        }
        let mut meta_scene = scene.clone();
        meta_scene.passes = job.passes.clone();
        let doc = metadata::build(
            &meta_scene,
            &RenderFacts {
                objects: objects.clone(),
                blender_version: facts_blender,
                blender_compat: facts_compat,
                passes: job.passes.clone(),
                user_materials: &opts.user_materials,
                config_hash: opts.config_hash.as_deref(),
            },
        );
        let meta_name = layout::metadata_file(&job.stem);
        let text = doc.to_json_pretty();
        staged.write(&meta_name, text.as_bytes())?;
        // The last check before the point of no return: an interrupt now drops the staged
        // files, so no partial sample is left.
        if slot.interrupted() {
            return Err(RenderError::Interrupted);
        }
        staged.commit()?;
        output::remove_other_outputs(&dir, &job.stem, &job.passes, opts.keep_exr);
        let _ = std::fs::remove_dir_all(&work);
        stats.attempt = attempt;
        stats.metadata = dir.join(meta_name);
        stats.build_s = reply.timings.build_s;
        stats.visibility_s = visibility_s;
        stats.render_s = reply.timings.render_s + reply.timings.shadow_render_s;
        stats.final_request_s = final_request_s;
        stats.post_s = t_post.elapsed().as_secs_f64();
        stats.projected = reply.projected.clone();
        stats.objects = objects;
        return Ok(());
    }
    Err(RenderError::TooManyRejects {
        index: job.index,
        attempts,
        threshold,
        width: size.0,
        height: size.1,
    })
}

/// Whether the geometry alone shows that some object of `scene` gets at most `threshold`
/// pixels in the visibility render ([`clevrtex_scene::visibility::visible_pixel_bounds`]).
fn prerejected(scene: &SceneFile, threshold: u64) -> bool {
    clevrtex_scene::visibility::visible_pixel_bounds(scene)
        .is_some_and(|b| b.iter().any(|&px| px <= threshold))
}

/// Whether the geometry alone shows that every object of `scene` gets more than `threshold`
/// pixels in the visibility render
/// ([`clevrtex_scene::visibility::visible_pixel_lower_bounds`]).
fn preaccepted(scene: &SceneFile, threshold: u64) -> bool {
    clevrtex_scene::visibility::visible_pixel_lower_bounds(scene)
        .is_some_and(|b| b.iter().all(|&px| px > threshold))
}

/// Count a rejected attempt and tell the run.
fn reject(
    slot: &dyn JobHost,
    job: &Job,
    attempt: u32,
    since: Instant,
    stats: &mut SampleStats,
    work: &Path,
) {
    let cost = since.elapsed();
    stats.rejects += 1;
    stats.reject_s += cost.as_secs_f64();
    if !work.as_os_str().is_empty() {
        let _ = std::fs::remove_dir_all(work);
    }
    slot.rejected(job.index, attempt, cost);
}
