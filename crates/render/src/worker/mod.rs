//! One long-lived Blender process speaking the bridge protocol (`docs/bridge-protocol.md`):
//! a [`Worker`] sends requests and waits for their replies, each wait with a deadline.
//!
//! - `process`: the process and its life (start, the threads reading its output, deadlines,
//!   kill, exit);
//! - `protocol`: the messages (the reply tag, requests, the replies and their checks, the
//!   feature negotiation of `ready`);
//! - `report`: what a worker reports (the bridge's timings, the output tails kept for error
//!   reports, `doctor`'s lines).

use std::path::{Path, PathBuf};
use std::sync::atomic::AtomicBool;
use std::sync::Arc;
use std::time::{Duration, Instant};

use crate::error::{Result, Tails};

mod process;
mod protocol;
mod report;

use process::Process;
use protocol::Unexpected;
pub use protocol::{BridgePhases, BridgeTimings, PhaseTime};
pub use protocol::{
    GroupImage, GroupSocket, InspectReply, MaterialMode, MaterialReply, MaterialSettings, Mode,
    Ready, RenderReply,
};

/// How long Blender may take to start and send `ready`: the
/// [`WorkerOptions::startup_timeout`] every command uses.
pub const STARTUP_TIMEOUT: Duration = Duration::from_secs(120);

/// How to start a worker.
#[derive(Debug, Clone)]
pub struct WorkerOptions {
    /// The Blender executable.
    pub blender: PathBuf,
    /// The bridge entry script (`worker.py` of a [`crate::BridgeDir`]).
    pub script: PathBuf,
    /// The resolved material catalogue file.
    pub materials: PathBuf,
    /// Cycles threads (0 = Blender's automatic choice).
    pub threads: u32,
    /// How long Blender may take to start and send `ready` (normally [`STARTUP_TIMEOUT`]).
    pub startup_timeout: Duration,
    /// Set to `true` (e.g. by a Ctrl-C handler) to abort any wait: the worker is killed and
    /// the call returns [`RenderError::Interrupted`].
    ///
    /// [`RenderError::Interrupted`]: crate::RenderError::Interrupted
    pub interrupt: Arc<AtomicBool>,
    /// The Cycles device this worker renders on (the CPU by default).
    pub device: crate::device::Placement,
}

impl WorkerOptions {
    /// A worker of `blender` running `bridge`'s script and catalogue, stopped by `interrupt`:
    /// Blender's own thread count, [`STARTUP_TIMEOUT`], the CPU. The one place a worker's
    /// options are assembled; change one with the `with_*` methods.
    pub fn new(
        blender: PathBuf,
        bridge: &crate::bridge::BridgeDir,
        interrupt: Arc<AtomicBool>,
    ) -> WorkerOptions {
        WorkerOptions {
            blender,
            script: bridge.worker_script(),
            materials: bridge.materials_json(),
            threads: 0,
            startup_timeout: STARTUP_TIMEOUT,
            interrupt,
            device: crate::device::Placement::cpu(),
        }
    }

    /// These options with `threads` Cycles threads (0 = Blender's choice).
    pub fn with_threads(mut self, threads: u32) -> WorkerOptions {
        self.threads = threads;
        self
    }

    /// These options with a start-up time limit of `timeout`.
    pub fn with_startup_timeout(mut self, timeout: Duration) -> WorkerOptions {
        self.startup_timeout = timeout;
        self
    }

    /// These options rendering on `device`.
    pub fn with_device(mut self, device: crate::device::Placement) -> WorkerOptions {
        self.device = device;
        self
    }

    /// Whether a worker started with these options is one started with `other`: what a
    /// worker fixes at start (its Blender, bridge script and catalogue, Cycles threads,
    /// device, interrupt flag) is the same; the start-up time limit is not compared (it only
    /// bounds the start). Such a worker may serve `other`'s requests (`crate::kept`).
    pub fn starts_like(&self, other: &WorkerOptions) -> bool {
        self.blender == other.blender
            && self.script == other.script
            && self.materials == other.materials
            && self.threads == other.threads
            && self.device == other.device
            && Arc::ptr_eq(&self.interrupt, &other.interrupt)
    }
}

/// A running Blender worker. Dropping it kills the process.
#[derive(Debug)]
pub struct Worker {
    process: Process,
    tag: String,
    next_id: u64,
    ready: Ready,
    startup: Duration,
}

impl Worker {
    /// Start Blender with the bridge and wait for its `ready` message.
    pub fn start(opts: &WorkerOptions) -> Result<Worker> {
        let started = Instant::now();
        let tag = protocol::fresh_tag();
        let args = protocol::bridge_args(&tag, opts.threads, &opts.materials, &opts.device);
        let mut process = Process::spawn(opts, &tag, &args)?;
        let doing = crate::error::STARTING_UP.to_string();
        let reply = next_reply(&mut process, Instant::now() + opts.startup_timeout, &doing)?;
        let ready: Ready = expect_type(&mut process, &reply, "ready", &doing)?;
        if let Err(problem) = protocol::check_version(&ready) {
            let line = reply.to_string();
            return Err(process.garbled(&doing, line, problem));
        }
        Ok(Worker {
            process,
            tag,
            next_id: 1,
            ready,
            startup: started.elapsed(),
        })
    }

    /// Also give up on a request when Blender prints nothing at all for `idle` (Cycles
    /// prints a line per sample, so a silent worker is hung even if the request's overall
    /// time limit is far away). `None` (the default) checks only the overall limit.
    pub fn set_idle_timeout(&mut self, idle: Option<Duration>) {
        self.process.set_idle_timeout(idle);
    }

    /// What the worker reported when it started.
    pub fn ready(&self) -> &Ready {
        &self.ready
    }

    /// How long start-up took (process start until `ready`).
    pub fn startup_time(&self) -> Duration {
        self.startup
    }

    /// The worker's reply tag.
    pub fn tag(&self) -> &str {
        &self.tag
    }

    /// Whether the worker died (crash, timeout, protocol error); a dead worker must be
    /// replaced.
    pub fn is_dead(&self) -> bool {
        self.process.is_dead()
    }

    /// The Blender process's id.
    pub fn pid(&self) -> u32 {
        self.process.pid()
    }

    /// The Blender process's resident memory now (`VmRSS` of `/proc/<pid>/status`), in bytes;
    /// `None` where there is no `/proc` or the process is gone.
    pub fn rss_bytes(&self) -> Option<u64> {
        let status = std::fs::read_to_string(format!("/proc/{}/status", self.pid())).ok()?;
        let kb: u64 = status
            .lines()
            .find_map(|l| l.strip_prefix("VmRSS:"))?
            .trim()
            .trim_end_matches("kB")
            .trim()
            .parse()
            .ok()?;
        kb.checked_mul(1024)
    }

    /// Refuse a scene whose `render` settings this worker's Blender cannot honour
    /// ([`protocol::Features::refusal`]: denoising without OIDN), before it renders anything.
    pub fn check_features(
        &self,
        render: &clevrtex_scene::scene_file::RenderSettings,
    ) -> Result<()> {
        match self
            .ready
            .features
            .refusal(render, &self.ready.blender_version)
        {
            Some(why) => Err(crate::RenderError::Refused(why)),
            None => Ok(()),
        }
    }

    /// Ask the worker to render `scene` (a scene file path) in `mode` into `out_dir`, and
    /// wait at most `timeout` for the reply. On timeout, crash or garbage the worker is
    /// killed (see [`Worker::is_dead`]); a [`RenderError::Bridge`] error leaves it usable.
    ///
    /// [`RenderError::Bridge`]: crate::RenderError::Bridge
    pub fn render(
        &mut self,
        scene: &Path,
        mode: Mode,
        out_dir: &Path,
        timeout: Duration,
    ) -> Result<RenderReply> {
        let label = scene.display().to_string();
        self.render_labelled(&label, scene, mode, out_dir, timeout)
    }

    /// Like [`Worker::render`], naming the scene `label` in error messages (e.g. its stem
    /// rather than a temporary path).
    pub fn render_labelled(
        &mut self,
        label: &str,
        scene: &Path,
        mode: Mode,
        out_dir: &Path,
        timeout: Duration,
    ) -> Result<RenderReply> {
        let doing = format!("rendering `{label}` ({})", mode.name());
        let request = protocol::render_request(mode, scene, out_dir);
        self.call(request, &doing, timeout)
    }

    /// Ask the worker to render material `name` of its catalogue on the small scene of
    /// `settings.mode`, into `out_dir/<name>.png` (`out_dir` must exist), and wait at most
    /// `timeout`. Failures as for [`Worker::render`]: a material that does not build is a
    /// [`RenderError::Bridge`] error and leaves the worker usable; a reply naming any other
    /// file than `out_dir/<name>.png`, or not a regular file, is a [`RenderError::Protocol`]
    /// error.
    ///
    /// [`RenderError::Bridge`]: crate::RenderError::Bridge
    /// [`RenderError::Protocol`]: crate::RenderError::Protocol
    pub fn material(
        &mut self,
        settings: &MaterialSettings,
        name: &str,
        out_dir: &Path,
        timeout: Duration,
    ) -> Result<MaterialReply> {
        let doing = format!("rendering material `{name}` ({})", settings.mode.name());
        let request = protocol::material_request(settings, name, out_dir);
        let reply: MaterialReply = self.call(request, &doing, timeout)?;
        // Blender's output is not trusted (docs/security.md): the file named must be the one
        // asked for, since callers read it and move it into their cache.
        if let Err(problem) = protocol::check_material_file(&reply, name, out_dir) {
            let line = reply.file.display().to_string();
            return Err(self.process.garbled(&doing, line, problem));
        }
        Ok(reply)
    }

    /// Ask the worker which node group of the `.blend` at `path` it would use (`group`, or
    /// the file's own as the public generator names it), with its sockets and textures; the
    /// bytes of its packed images are written into `packed_dir`.
    /// A `.blend` without a usable group is a [`RenderError::Bridge`] error.
    ///
    /// [`RenderError::Bridge`]: crate::RenderError::Bridge
    pub fn inspect(
        &mut self,
        path: &Path,
        group: Option<&str>,
        packed_dir: Option<&Path>,
        timeout: Duration,
    ) -> Result<InspectReply> {
        let doing = format!("inspecting the user material `{}`", path.display());
        let request = protocol::inspect_request(path, group, packed_dir);
        self.call(request, &doing, timeout)
    }

    /// Send `request` (an object; its `id` is added here) and wait at most `timeout` for its
    /// `done` reply.
    fn call<T: serde::de::DeserializeOwned>(
        &mut self,
        mut request: serde_json::Value,
        doing: &str,
        timeout: Duration,
    ) -> Result<T> {
        let id = self.next_id;
        self.next_id += 1;
        request["id"] = id.into();
        self.process.send(&request, doing)?;
        let reply = next_reply(&mut self.process, Instant::now() + timeout, doing)?;
        if let Err(problem) = protocol::check_id(&reply, id) {
            let line = reply.to_string();
            return Err(self.process.garbled(doing, line, problem));
        }
        expect_type(&mut self.process, &reply, "done", doing)
    }

    /// Ask the worker to quit and wait briefly for it; kills it if it lingers.
    pub fn quit(mut self) {
        let _ = self.process.send(&protocol::quit_request(), "quitting");
        self.process.close(Duration::from_secs(5));
    }

    /// Current output tails. After the process died, waits briefly for its last stderr
    /// lines (the reader thread may still be draining the pipe).
    pub fn tails(&self) -> Tails {
        self.process.tails()
    }
}

/// Wait for the next reply of `process` until `deadline`: a JSON object, or the process is
/// killed for garbage.
fn next_reply(process: &mut Process, deadline: Instant, doing: &str) -> Result<serde_json::Value> {
    let text = process.next_reply(deadline, doing)?;
    protocol::parse_line(&text).map_err(|problem| process.garbled(doing, text, problem))
}

/// `reply` as the `expected` reply type `T`. The bridge's `error` reply is a
/// [`RenderError::Bridge`] error and leaves the process usable; any other reply kills it.
///
/// [`RenderError::Bridge`]: crate::RenderError::Bridge
fn expect_type<T: serde::de::DeserializeOwned>(
    process: &mut Process,
    reply: &serde_json::Value,
    expected: &str,
    doing: &str,
) -> Result<T> {
    protocol::expect_type(reply, expected, doing).map_err(|e| match e {
        Unexpected::Failed(err) => err,
        Unexpected::Garbled(problem) => process.garbled(doing, reply.to_string(), problem),
    })
}
