//! The Blender session of the commands that render outside the pool (`bench render`,
//! `materials sheet|check|stats|cost`, the user-material checks): a [`Session`] (the same
//! restart-and-retry policy as `generate`) together with its bridge folder, and a warning on
//! stderr for each restart.

use std::path::PathBuf;
use std::sync::atomic::AtomicBool;
use std::sync::Arc;
use std::time::Duration;

use crate::bridge::BridgeDir;
use crate::error::{RenderError, Result};
use crate::session::{Hooks, Session};
use crate::worker::{Ready, Worker, WorkerOptions};

/// Prints each restart the way `generate` does.
struct WarnOnRestart;

impl Hooks for WarnOnRestart {
    fn restarting(&mut self, error: &RenderError) {
        eprintln!("warning: restarting a Blender worker: {error}");
    }
}

/// How to start the session's workers.
pub struct Settings {
    /// The Blender executable.
    pub blender: PathBuf,
    /// The resolved material catalogue for the bridge.
    pub materials_json: String,
    /// Cycles threads (0 = Blender's choice).
    pub threads: u32,
    /// Restarts of a crashed or hung worker per request.
    pub retries: u32,
    /// A worker silent this long counts as hung (see `Worker::set_idle_timeout`).
    pub idle_timeout: Option<Duration>,
    /// Set by the command's Ctrl-C handler.
    pub interrupt: Arc<AtomicBool>,
    /// Time limit for a worker to start.
    pub startup_timeout: Duration,
}

/// A restartable Blender worker and the bridge folder it runs from.
pub struct BlenderSession {
    // Declared first so it is dropped first: the worker dies before its folder goes.
    session: Session,
    _bridge: BridgeDir,
}

impl BlenderSession {
    /// Write the bridge; the first worker starts with the first request (or [`Self::ready`]).
    pub fn new(settings: Settings) -> Result<BlenderSession> {
        let bridge = BridgeDir::create(&settings.materials_json)?;
        let session = Session::new(
            WorkerOptions::new(settings.blender, &bridge, settings.interrupt)
                .with_threads(settings.threads)
                .with_startup_timeout(settings.startup_timeout),
            settings.retries,
            settings.idle_timeout,
        );
        Ok(BlenderSession {
            session,
            _bridge: bridge,
        })
    }

    /// What the worker reported when it started (starting it if needed).
    pub fn ready(&mut self) -> Result<Ready> {
        let worker = self.session.worker(&mut WarnOnRestart)?;
        Ok(worker.ready().clone())
    }

    /// Run `call` on a worker, restarting and retrying after worker failures (see
    /// [`Session::request`]).
    pub fn request<T>(&mut self, call: impl FnMut(&mut Worker) -> Result<T>) -> Result<T> {
        self.session.request(&mut WarnOnRestart, call)
    }

    /// Let the worker quit (or kill it after Ctrl-C).
    pub fn close(mut self) {
        self.session.close();
    }
}
