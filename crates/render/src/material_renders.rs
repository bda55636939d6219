//! The Blender renders of `clevrtex materials sheet|check|stats|cost|parity`: one worker for a
//! batch of materials (a [`BlenderSession`]: `generate`'s restart-and-retry policy, Ctrl-C
//! stopping Blender), one `material` request per material (`docs/bridge-protocol.md`), or for
//! `parity` one `render` request per scene file ([`render_scene`]).

use std::path::{Path, PathBuf};
use std::sync::atomic::AtomicBool;
use std::sync::Arc;
use std::time::Duration;

use clevrtex_materials::Catalogue;

use crate::command_session::{BlenderSession, Settings};
use crate::error::{RenderError, Result};
use crate::user_materials::{check_before_run, Checked};
use crate::worker::{MaterialReply, MaterialSettings, Mode};

/// How the materials are rendered: the Blender and the limits of its worker (the values of
/// `materials`'s `--blender`, `--threads`, `--timeout`, `--retries` and `--startup-timeout`,
/// checked by the command).
#[derive(Debug, Clone)]
pub struct RenderOptions {
    /// The Blender executable.
    pub blender: PathBuf,
    /// Cycles threads (0: automatic).
    pub threads: u32,
    /// Time limit per material render (`None`: by the render's size and samples).
    pub timeout: Option<Duration>,
    /// Restarts of a crashed or hung worker per material.
    pub retries: u32,
    /// Time limit for a worker to start.
    pub startup_timeout: Duration,
    /// Set by the command's Ctrl-C handler; stops Blender.
    pub interrupt: Arc<AtomicBool>,
}

/// How one material's render came out.
pub enum Outcome {
    /// Rendered.
    Done(MaterialReply),
    /// The bridge could not build or render it (the worker survived).
    Failed {
        /// The bridge's message.
        message: String,
        /// The Python traceback (may be empty).
        traceback: String,
    },
}

/// One Blender worker for the materials `names` of `cat`, started on the first render. User
/// materials among `names` are checked first, as for `generate` ([`check_before_run`]: every
/// bad file named at once), and the worker reads only their checked copies, which live as
/// long as the returned [`Checked`].
pub fn session(
    cat: &Catalogue,
    names: &[&str],
    a: &RenderOptions,
) -> Result<(BlenderSession, Checked)> {
    let mut cat = cat.clone();
    let used = names.iter().map(|n| n.to_string()).collect();
    let checked = check_before_run(
        &mut cat,
        &used,
        &a.blender,
        a.startup_timeout,
        a.interrupt.clone(),
    )?;
    let session = BlenderSession::new(Settings {
        blender: a.blender.clone(),
        materials_json: cat.resolved_json_for(names.iter().copied()),
        threads: a.threads,
        retries: a.retries,
        // With an explicit `--timeout` that limit is the only one, as in `generate`.
        idle_timeout: a.timeout.is_none().then_some(crate::pool::IDLE_TIMEOUT),
        interrupt: a.interrupt.clone(),
        startup_timeout: a.startup_timeout,
    })?;
    Ok((session, checked))
}

/// The time limit of one render: `--timeout`, else 600 s + 8 s per sample at 320x240 (the
/// rule `generate` uses for scenes).
fn timeout(a: &RenderOptions, s: &MaterialSettings) -> Duration {
    limit(a, (s.size, s.size), s.samples)
}

fn limit(a: &RenderOptions, (width, height): (u32, u32), samples: u32) -> Duration {
    let pixels = f64::from(width) * f64::from(height) / (320.0 * 240.0);
    let auto = 600.0 + 8.0 * f64::from(samples) * pixels.max(0.05);
    a.timeout.unwrap_or(Duration::from_secs_f64(auto))
}

/// Render `scene` (`label` in messages) as `generate` renders a scene file (the final render
/// of its passes), written as `out_dir/scene.json` (`out_dir` must exist), into `out_dir`,
/// under the time limit of [`timeout`]'s rule at the scene's size and samples; the multilayer
/// EXR of the passes, checked to be a file the reply names in `out_dir` (Blender's output is
/// not trusted).
pub fn render_scene(
    session: &mut BlenderSession,
    a: &RenderOptions,
    label: &str,
    scene: &clevrtex_scene::SceneFile,
    out_dir: &Path,
) -> Result<PathBuf> {
    let path = out_dir.join("scene.json");
    clevrtex_scene::to_pretty_json(scene)
        .map_err(std::io::Error::other)
        .and_then(|json| clevrtex_dataset::atomic::write(&path, json.as_bytes()))
        .map_err(|cause| RenderError::write(path.clone(), cause))?;
    let r = &scene.render;
    let limit = limit(a, (r.width, r.height), r.samples);
    let reply =
        session.request(|w| w.render_labelled(label, &path, Mode::Final, out_dir, limit))?;
    reply.file("passes", out_dir)
}

/// Render each of `names` with `settings` into `out_dir/<name>.png`, in order. A material the
/// bridge cannot build is an [`Outcome::Failed`] and the batch goes on; a worker that keeps
/// failing (after `--retries` restarts) or an interrupt ends it with an error.
pub fn render_all(
    session: &mut BlenderSession,
    a: &RenderOptions,
    settings: &MaterialSettings,
    names: &[&str],
    out_dir: &Path,
) -> Result<Vec<Outcome>> {
    std::fs::create_dir_all(out_dir).map_err(|cause| {
        RenderError::io(
            "cannot create",
            out_dir.to_path_buf(),
            cause,
            "make the folder writable, or free disk space",
        )
    })?;
    let limit = timeout(a, settings);
    names
        .iter()
        .map(
            |name| match session.request(|w| w.material(settings, name, out_dir, limit)) {
                Ok(reply) => Ok(Outcome::Done(reply)),
                Err(RenderError::Bridge {
                    message, traceback, ..
                }) => Ok(Outcome::Failed { message, traceback }),
                Err(e) => Err(e),
            },
        )
        .collect()
}

/// [`render_all`] into `dir`, which is removed afterwards whatever happened.
pub fn render_all_in_temp(
    session: &mut BlenderSession,
    a: &RenderOptions,
    settings: &MaterialSettings,
    names: &[&str],
    dir: &Path,
) -> Result<Vec<Outcome>> {
    let result = render_all(session, a, settings, names, dir);
    let _ = std::fs::remove_dir_all(dir);
    result
}

/// Render the sheet cells of `missing` with `settings` into `cache` (as `key(name)`), through
/// a temporary folder there that is removed whatever happened; the materials the bridge could
/// not build come back as `name: message` lines.
pub fn render_into_cache(
    cat: &Catalogue,
    missing: &[&str],
    a: &RenderOptions,
    settings: &MaterialSettings,
    cache: &Path,
    key: &dyn Fn(&str) -> String,
) -> Result<Vec<String>> {
    let tmp = cache.join(format!("tmp-{}", std::process::id()));
    let (mut session, _checked) = session(cat, missing, a)?;
    let result = render_all(&mut session, a, settings, missing, &tmp).and_then(|outcomes| {
        session.close();
        let mut failed = Vec::new();
        for (name, outcome) in missing.iter().zip(outcomes) {
            match outcome {
                Outcome::Done(reply) => {
                    std::fs::rename(&reply.file, cache.join(key(name))).map_err(|cause| {
                        RenderError::io(
                            "cannot move into the cache",
                            reply.file.clone(),
                            cause,
                            "make the cache folder writable, or free disk space",
                        )
                    })?;
                }
                Outcome::Failed { message, .. } => failed.push(format!("{name}: {message}")),
            }
        }
        Ok(failed)
    });
    let _ = std::fs::remove_dir_all(&tmp);
    result
}
