//! One job: the attempt and visibility policy that turns a [`Job`] into a written sample.
//!
//! Per job: sample the scene (attempt 0), render the cheap visibility pass, count each
//! object's pixels and, if one is at or under the threshold, resample with the next attempt
//! number (deterministic: the attempt goes into the seed) before paying for the full render.
//! The final mask confirms the counts.

use std::path::{Path, PathBuf};
use std::sync::atomic::Ordering;
use std::sync::Arc;
use std::time::{Duration, Instant};

use clevrtex_scene::{layout, Pass, SceneFile};

use crate::error::{RenderError, Result};
use crate::exr_io::Channels;
use crate::metadata::{self, RenderFacts};
use crate::output::{self, Staged};
use crate::passes::write_passes;
use crate::pool::{PoolEvent, Slot};
use crate::post::{self, ObjectPixels};
use crate::worker::{Mode, RenderReply};

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
    /// Wall time of the rejected attempts.
    pub reject_s: f64,
    /// Blender's projection of each object origin (`[x, y, depth]`).
    pub projected: Vec<[f64; 3]>,
    /// Per-object visibility in the final mask.
    pub objects: Vec<ObjectPixels>,
}

impl Slot<'_, '_> {
    pub(crate) fn run_job(&mut self, job: &Job) -> Result<SampleStats> {
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
        let mut size = (0, 0);
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
            size = (scene.render.width, scene.render.height);
            let work = self.scratch.path().join(format!("{}-{attempt}", job.stem));
            let _ = std::fs::remove_dir_all(&work);
            std::fs::create_dir_all(&work).map_err(|e| RenderError::write(&work, e))?;
            let scene_path = work.join("scene.json");
            let text = serde_json::to_string_pretty(&scene).expect("scene serialises");
            post::write_file(&scene_path, text.as_bytes())?;
            let timeout = opts.timeout.unwrap_or_else(|| auto_timeout(&scene));
            let n = scene.objects.len();
            let label = match &job.source {
                Some(file) => format!("{} (scene file `{}`)", job.stem, file.display()),
                None => format!("{} attempt {attempt}", job.stem),
            };

            let mut visibility_s = 0.0;
            if job.resample && opts.visibility_check {
                let t = Instant::now();
                let reply = self.request(&label, &scene_path, Mode::Visibility, &work, timeout)?;
                stats.visibility_build_s += reply.timings.build_s;
                stats.visibility_render_s += reply.timings.render_s;
                stats.visibility_passes += 1;
                let exr = reply_file(&reply, "visibility", &work)?;
                let ch = Channels::read_sized(&exr, (size.0 as usize, size.1 as usize))?;
                let ids = post::instance_ids(ch.get(&crate::passes::index_channel())?, n, &exr)?;
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
            let (facts_blender, facts_compat) = self
                .session
                .current()
                .map(|w| (w.ready().blender_version.clone(), w.ready().compat.clone()))
                .unwrap_or_default();
            let dir = layout::sample_dir(&opts.out, &job.variant, job.index);
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
                    blender_compat: facts_compat,
                    passes: job.passes.clone(),
                },
            );
            let meta_name = layout::metadata_file(&job.stem);
            let text = doc.to_json_pretty();
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
            stats.render_s = reply.timings.render_s + reply.timings.shadow_render_s;
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
            width: size.0,
            height: size.1,
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

/// A file the bridge says it wrote, which must be a regular file directly in our scratch
/// folder `work`.
pub(crate) fn reply_file(reply: &RenderReply, role: &str, work: &Path) -> Result<PathBuf> {
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
    // Blender's output is not trusted (docs/security.md): a reply naming a file elsewhere
    // (`/home/me/secret`, `work/../x`, a link out of `work`) would have it read and copied into
    // the dataset.
    if path.parent() != Some(work) || path.file_name().is_none() {
        return Err(RenderError::BadOutput {
            path: path.clone(),
            problem: format!(
                "the `{role}` file the bridge reported is not in the worker's folder `{}`; it was not read",
                work.display()
            ),
        });
    }
    match std::fs::symlink_metadata(path) {
        Ok(m) if m.is_file() => Ok(path.clone()),
        Ok(_) => Err(RenderError::BadOutput {
            path: path.clone(),
            problem: format!(
                "the `{role}` file the bridge reported is not a regular file (a link, folder or FIFO); it was not read"
            ),
        }),
        Err(_) => Err(RenderError::BadOutput {
            path: path.clone(),
            problem: format!("the `{role}` file the bridge reported does not exist"),
        }),
    }
}
