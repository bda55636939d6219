//! A restartable Blender worker: the one place that starts workers, replaces a crashed, hung
//! or babbling one and retries the request.
//!
//! Every user of Blender goes through a [`Session`]: each thread of [`crate::pool::run`]
//! (`generate`, `render`), `clevrtex bench render` and the `clevrtex materials` renders. So
//! they share one policy: a request that fails with a worker failure
//! ([`RenderError::is_worker_failure`]: timeout, crash, malformed reply) kills the worker,
//! a fresh one is started and the request is sent again, up to `retries` times; an interrupt
//! (the [`WorkerOptions::interrupt`] flag, set by a Ctrl-C handler) kills the worker at once
//! and returns [`RenderError::Interrupted`]; a bridge error (a bad scene or material) is
//! returned as is and leaves the worker running.
//!
//! ```no_run
//! use std::time::Duration;
//! use std::sync::{atomic::AtomicBool, Arc};
//! use clevrtex_render::{BridgeDir, Mode, Session, WorkerOptions};
//!
//! # fn main() -> Result<(), clevrtex_render::RenderError> {
//! let bridge = BridgeDir::create(&clevrtex_render::default_materials_json().unwrap())?;
//! let mut session = Session::new(
//!     WorkerOptions::new(
//!         clevrtex_render::blender::locate(None)?,
//!         &bridge,
//!         Arc::new(AtomicBool::new(false)),
//!     ),
//!     2,    // restarts per request
//!     None, // no idle limit
//! );
//! let out = std::path::Path::new("/tmp/out");
//! let reply = session.request(&mut (), |w| {
//!     w.render(&out.join("scene.json"), Mode::Final, out, Duration::from_secs(600))
//! })?;
//! session.close();
//! # Ok(()) }
//! ```

use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::Duration;

use crate::error::{RenderError, Result};
use crate::worker::{Worker, WorkerOptions};

/// What a session reports while it works, and whether it should give up early.
///
/// `()` implements it with no reports; the pool counts starts and forwards them as
/// [`crate::PoolEvent`]s; the commands print a warning on each restart.
pub trait Hooks {
    /// A worker started (the first one, or a replacement).
    fn started(&mut self, _worker: &Worker) {}
    /// A worker failed with `error` and is replaced for another try.
    fn restarting(&mut self, _error: &RenderError) {}
    /// Whether to stop instead of restarting a failed worker (besides the interrupt flag,
    /// which is always checked), e.g. because another thread of the run hit a fatal error.
    fn stopping(&self) -> bool {
        false
    }
}

impl Hooks for () {}

/// A (re)startable Blender worker with a restart-and-retry policy. Starts its worker on the
/// first request; dropping the session kills it.
#[derive(Debug)]
pub struct Session {
    options: WorkerOptions,
    retries: u32,
    idle_timeout: Option<Duration>,
    ever_started: Arc<AtomicBool>,
    worker: Option<Worker>,
}

impl Session {
    /// A session starting workers with `options`, restarting a failed one up to `retries`
    /// times per request. `idle_timeout`: see [`Worker::set_idle_timeout`].
    pub fn new(options: WorkerOptions, retries: u32, idle_timeout: Option<Duration>) -> Session {
        Session {
            options,
            retries,
            idle_timeout,
            ever_started: Arc::new(AtomicBool::new(false)),
            worker: None,
        }
    }

    /// Share the "some worker has started" flag with the other sessions of a run. Until any
    /// worker has started, a start failure is a [`RenderError::WorkerStart`] (a wrong program
    /// or a broken install would fail every request the same way, so callers stop there);
    /// afterwards it is an ordinary error of the one request.
    pub fn sharing_start_flag(mut self, flag: Arc<AtomicBool>) -> Session {
        self.ever_started = flag;
        self
    }

    /// The options its workers start with.
    pub fn options(&self) -> &WorkerOptions {
        &self.options
    }

    /// Restart a failed worker up to `retries` times per request from now on, and give up on
    /// a request when the worker is silent for `idle_timeout` ([`Worker::set_idle_timeout`];
    /// the running worker's too): a kept session taken by another run (`crate::kept`).
    pub fn set_policy(&mut self, retries: u32, idle_timeout: Option<Duration>) {
        self.retries = retries;
        self.idle_timeout = idle_timeout;
        if let Some(w) = self.worker.as_mut() {
            w.set_idle_timeout(idle_timeout);
        }
    }

    /// The running worker, if any (none before the first request, or after a failure).
    pub fn current(&self) -> Option<&Worker> {
        self.worker.as_ref().filter(|w| !w.is_dead())
    }

    /// A running worker, starting one if there is none or the last one died.
    pub fn worker(&mut self, hooks: &mut dyn Hooks) -> Result<&mut Worker> {
        if self.worker.as_ref().is_some_and(Worker::is_dead) {
            self.worker = None;
        }
        if self.worker.is_none() {
            let mut w = match Worker::start(&self.options) {
                Ok(w) => w,
                Err(e) if !self.ever_started.load(Ordering::SeqCst) => {
                    return Err(RenderError::WorkerStart(Box::new(e)))
                }
                Err(e) => return Err(e),
            };
            w.set_idle_timeout(self.idle_timeout);
            self.ever_started.store(true, Ordering::SeqCst);
            hooks.started(&w);
            self.worker = Some(w);
        }
        Ok(self.worker.as_mut().expect("just started"))
    }

    /// Run `call` on a running worker. A worker failure kills the worker; a fresh one runs
    /// `call` again, up to `retries` times, unless the run is interrupted or stopping (then
    /// [`RenderError::Interrupted`]). Any other error is returned at once.
    pub fn request<T>(
        &mut self,
        hooks: &mut dyn Hooks,
        mut call: impl FnMut(&mut Worker) -> Result<T>,
    ) -> Result<T> {
        let mut tries = 0;
        loop {
            let result = self.worker(hooks).and_then(&mut call);
            match result {
                Err(e) if e.is_worker_failure() && tries < self.retries => {
                    tries += 1;
                    self.worker = None;
                    hooks.restarting(&e);
                    if hooks.stopping() || self.options.interrupt.load(Ordering::SeqCst) {
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

    /// End the session: ask a live worker to quit, or kill it at once after an interrupt.
    pub fn close(&mut self) {
        if let Some(w) = self.worker.take() {
            if self.options.interrupt.load(Ordering::SeqCst) {
                drop(w); // kills
            } else {
                w.quit();
            }
        }
    }
}
