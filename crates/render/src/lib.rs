//! Drives headless Blender to render scene files, and turns its output into the published
//! dataset layout.
//!
//! - [`Worker`]: one long-lived Blender process running the embedded bridge
//!   (`blender_scripts/`, see `docs/bridge-protocol.md`); it renders many scenes, with a
//!   deadline on every request.
//! - [`Pool`]: `N` workers rendering jobs in parallel, with the visibility-first check,
//!   bounded retries, restarts, a failure ledger, resume and crash-safe output.
//! - [`output`]: the file layout; [`post`]: the pass encodings.
//!
//! Rendering one scene file into a folder (what a contact sheet or a benchmark needs):
//!
//! ```no_run
//! use std::sync::{atomic::AtomicBool, Arc};
//! use std::time::Duration;
//! use clevrtex_render::{BridgeDir, Mode, Worker, WorkerOptions};
//!
//! # fn main() -> Result<(), clevrtex_render::RenderError> {
//! let bridge = BridgeDir::create(&clevrtex_render::default_materials_json())?;
//! let mut worker = Worker::start(&WorkerOptions {
//!     blender: clevrtex_render::blender::locate(None)?,
//!     script: bridge.worker_script(),
//!     materials: bridge.materials_json(),
//!     threads: 0,
//!     startup_timeout: Duration::from_secs(120),
//!     interrupt: Arc::new(AtomicBool::new(false)),
//! })?;
//! let out = std::path::Path::new("/tmp/out");
//! let reply = worker.render(&out.join("scene.json"), Mode::Final, out, Duration::from_secs(600))?;
//! println!("rgb at {:?}", reply.files.get("rgb"));
//! # Ok(()) }
//! ```
#![deny(missing_docs)]

pub mod blender;
pub mod bridge;
mod error;
pub mod exr_io;
pub mod output;
pub mod post;
mod worker;

pub use bridge::BridgeDir;
pub use error::{RenderError, Result, Tails};
pub use worker::{BridgeTimings, Mode, Ready, RenderReply, Worker, WorkerOptions};

/// The resolved material catalogue for the bridge (`materials.json`, see
/// `docs/bridge-protocol.md`): every catalogue material by name.
pub fn default_materials_json() -> String {
    let names: Vec<String> =
        serde_json::from_str::<serde_json::Value>(clevrtex_materials::CATALOGUE_JSON)
            .ok()
            .and_then(|v| v.get("materials").cloned())
            .and_then(|m| m.as_array().cloned())
            .unwrap_or_default()
            .iter()
            .filter_map(|m| m.get("name").and_then(|n| n.as_str()).map(String::from))
            .collect();
    let materials: serde_json::Map<String, serde_json::Value> = names
        .into_iter()
        .map(|n| (n, serde_json::json!({})))
        .collect();
    serde_json::json!({"version": 1, "materials": materials}).to_string()
}
