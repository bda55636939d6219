//! What `clevrtex doctor` asks of a Blender: whether the embedded bridge starts in it and what
//! its worker then reports ([`probe`]), for the Blender checked and for every Blender found
//! ([`probe_all`], in parallel). The command prints.

use std::path::{Path, PathBuf};
use std::sync::atomic::AtomicBool;
use std::sync::Arc;
use std::time::Duration;

use crate::blender::{self, Flavour};
use crate::bridge::BridgeDir;
use crate::error::Result;
use crate::worker::{Ready, Worker, WorkerOptions};

/// A worker that started: what it reported and how long it took.
pub struct Probe {
    /// The worker's `ready` message.
    pub ready: Ready,
    /// Seconds from the start to `ready`.
    pub startup_s: f64,
}

/// Start one single-threaded worker of `blender` running the bridge with the catalogue
/// `materials_json`, on the default device, within `deadline`; what it reported. The worker
/// quits at once.
pub fn probe(blender: &Path, materials_json: &str, deadline: Duration) -> Result<Probe> {
    let bridge = BridgeDir::create(materials_json)?;
    let worker = Worker::start(
        &WorkerOptions::new(
            blender.to_path_buf(),
            &bridge,
            Arc::new(AtomicBool::new(false)),
        )
        .with_threads(1)
        .with_startup_timeout(deadline),
    )?;
    let probe = Probe {
        ready: worker.ready().clone(),
        startup_s: worker.startup_time().as_secs_f64(),
    };
    worker.quit();
    Ok(probe)
}

/// One Blender found (PATH, `CLEVRTEX_BLENDER`, `./.venv-bpy`) and what it answered.
pub struct Found {
    /// Its path.
    pub path: PathBuf,
    /// Where it was found.
    pub from: &'static str,
    /// Whether it is the one `generate` uses.
    pub used: bool,
    /// A Blender executable or a Python with `bpy`.
    pub flavour: Flavour,
    /// Its `--version` line, or why there is none (first line of the error).
    pub version: std::result::Result<String, String>,
    /// What its worker reported, or why the bridge did not start (first line of the error).
    pub probe: std::result::Result<Ready, String>,
}

/// Every Blender found, probed in parallel (its version, then a worker with an empty
/// catalogue), each within `deadline`; `used` is the one `generate` uses (`None`: none).
pub fn probe_all(used: Option<&Path>, deadline: Duration) -> Vec<Found> {
    let same = |a: &Path, b: &Path| std::fs::canonicalize(a).ok() == std::fs::canonicalize(b).ok();
    let first_line =
        |e: crate::error::RenderError| e.to_string().lines().next().unwrap_or("").to_string();
    let found = blender::candidates();
    std::thread::scope(|s| {
        let handles: Vec<_> = found
            .into_iter()
            .map(|(path, from)| {
                s.spawn(move || Found {
                    used: used.is_some_and(|u| same(u, &path)),
                    flavour: blender::flavour(&path),
                    version: blender::version_line_within(&path, deadline).map_err(first_line),
                    probe: probe(&path, "{\"materials\": {}}", deadline)
                        .map(|p| p.ready)
                        .map_err(first_line),
                    path,
                    from,
                })
            })
            .collect();
        handles.into_iter().filter_map(|h| h.join().ok()).collect()
    })
}
