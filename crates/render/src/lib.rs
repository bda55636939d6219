//! Drives headless Blender to render scene files, and turns its output into the published
//! dataset layout.
//!
//! - [`Worker`]: one long-lived Blender process running the embedded bridge
//!   (`blender_scripts/`, see `docs/bridge-protocol.md`); it renders many scenes (and single
//!   materials, [`Worker::material`]), with a deadline on every request.
//! - [`Session`]: a restartable worker: the one restart-and-retry policy (timeouts, crashes,
//!   Ctrl-C) shared by the pool, `clevrtex bench` and `clevrtex materials`.
//! - [`pool::run`]: `N` workers rendering [`Job`]s in parallel, with the visibility-first
//!   check, bounded retries, restarts, a failure ledger, resume and crash-safe output; this
//!   is what `clevrtex generate` and `clevrtex render` call.
//! - [`output`]: writing a sample into the layout (`clevrtex_dataset::layout`); [`post`]: the
//!   pass encodings.
//!
//! Rendering one scene file into a folder with a bare worker (no restarts; see [`Session`]
//! for a worker that survives crashes):
//!
//! ```no_run
//! use std::sync::{atomic::AtomicBool, Arc};
//! use std::time::Duration;
//! use clevrtex_render::{BridgeDir, Mode, Worker, WorkerOptions};
//!
//! # fn main() -> Result<(), clevrtex_render::RenderError> {
//! let materials = clevrtex_render::default_materials_json().expect("valid built-in catalogue");
//! let bridge = BridgeDir::create(&materials)?;
//! let mut worker = Worker::start(&WorkerOptions::new(
//!     clevrtex_render::blender::locate(None)?,
//!     &bridge,
//!     Arc::new(AtomicBool::new(false)),
//! ))?;
//! let out = std::path::Path::new("/tmp/out");
//! let reply = worker.render(&out.join("scene.json"), Mode::Final, out, Duration::from_secs(600))?;
//! println!("rgb at {:?}", reply.files.get("rgb"));
//! # Ok(()) }
//! ```
#![deny(missing_docs)]

// The files' layers, lowest first. A file uses files of lower layers (or of its own, without
// a circle), never of a higher one and never the crate root's re-exports: what a lower file
// needs from above comes in as an argument (the ledger gets an image's index, stem and
// variant, not a `Job`; `passes` gets the bridge's file lookup, not a `RenderReply`). A
// dataset on disk (its layout, reader, manifests, lock, `verify`, `export`, card) is the
// `clevrtex-dataset` crate's, below this one.
//   1. error, group, device, tmp: messages, process groups, the device plan, temporary folders
//   2. blender, bridge, exr_io, post: finding Blender, the embedded bridge, EXRs, encodings
//   3. output, metadata, passes, ledger: a sample and the failure ledger written to disk
//   4. worker (process, protocol, report): one Blender process
//   5. session, gpu_probe, job, doctor: a worker restarted, asked for its GPUs, rendering one
//      image, asked what it has (`doctor`; doctor_text: what `doctor` prints of it); kept:
//      workers kept between the pool runs of one command (a suite's variants)
//   6. pool, command_session: the run; one restartable worker for the commands outside it;
//      run_text: what a run prints, as text
//   7. user_materials (copies): user materials checked and copied before a run renders
//   8. material_renders: `clevrtex materials`' renders of single materials; planner: the
//      model of `generate --estimate` and its calibration run, planner_text its checks and text;
//      scene_jobs, generate: the jobs of `render` and `generate`
//   9. batch: a run of `generate` or `render` (its pool planned and run, manifest, card)

pub mod batch;
pub mod blender;
pub mod bridge;
pub mod command_session;
pub mod device;
pub mod doctor;
pub mod doctor_text;
mod error;
pub mod exr_io;
pub mod generate;
pub mod gpu_probe;
pub mod group;
mod job;
pub mod kept;
mod ledger;
pub mod material_renders;
pub mod metadata;
pub mod output;
mod passes;
pub mod planner;
pub mod planner_text;
pub mod pool;
pub mod post;
pub mod run_text;
pub mod scene_jobs;
mod session;
pub mod tmp;
pub mod user_materials;
mod worker;

pub use bridge::BridgeDir;
pub use error::{RenderError, Result, Tails};
pub use pool::{Job, PoolEvent, PoolOptions, RunReport, SampleStats};
pub use session::{Hooks, Session};
pub use worker::{
    BridgePhases, BridgeTimings, GroupImage, GroupSocket, InspectReply, MaterialMode,
    MaterialReply, MaterialSettings, Mode, PhaseTime, Ready, RenderReply, Worker, WorkerOptions,
    STARTUP_TIMEOUT,
};

/// The resolved built-in material catalogue for the bridge (`materials.json`, see
/// `docs/bridge-protocol.md`), from `clevrtex-materials`. Fails only if the embedded
/// catalogue is invalid (a bug), with the catalogue's own message.
pub fn default_materials_json() -> std::result::Result<String, String> {
    clevrtex_materials::Catalogue::builtin()
        .map(|c| c.resolved_json())
        .map_err(|e| e.to_string())
}
