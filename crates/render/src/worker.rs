//! One long-lived Blender process speaking the bridge protocol (`docs/bridge-protocol.md`).
//!
//! The worker's stdout and stderr are read by two threads so Blender can never block on a
//! full pipe; only stdout lines starting with the worker's random tag are replies, every
//! other line is Blender's chatter and only kept as a tail for error reports. Every wait has
//! a deadline: on expiry the process is killed and reaped.

use std::collections::{BTreeMap, VecDeque};
use std::hash::{BuildHasher, Hasher};
use std::io::{BufRead, BufReader, Read, Write};
use std::path::{Path, PathBuf};
use std::process::{Child, ChildStdin, Stdio};
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::mpsc::{self, Receiver, RecvTimeoutError};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use serde::Deserialize;

use crate::error::{RenderError, Result, Tails};

/// Lines of stdout and of stderr kept for error reports.
const TAIL_LINES: usize = 25;
/// Longest line of Blender's output that is kept (protocol replies are a few KB).
const MAX_LINE: usize = 1 << 20;
/// Longest line kept in the error tails.
const MAX_TAIL_LINE: usize = 4096;
/// Reply lines waiting to be read: a worker that floods the reply stream blocks on its pipe
/// instead of filling our memory.
const MAX_PENDING_REPLIES: usize = 64;
/// How often a wait re-checks the child's status and the interrupt flag.
const POLL: Duration = Duration::from_millis(50);
/// After stdout closes, how long to wait for the exit status before killing.
const EXIT_GRACE: Duration = Duration::from_secs(3);

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
        bridge: &crate::BridgeDir,
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
}

/// The worker's `ready` message.
#[derive(Debug, Clone, Deserialize)]
pub struct Ready {
    /// Protocol version of the bridge.
    pub bridge_version: u64,
    /// Blender's version, e.g. `3.4.1`.
    pub blender_version: String,
    /// Cycles devices the bridge found, e.g. `["CPU"]`.
    #[serde(default)]
    pub cycles_devices: Vec<String>,
    /// The GPUs Cycles can render on, in its order.
    #[serde(default)]
    pub gpus: Vec<crate::device::Gpu>,
    /// The CUDA kernels this build's Cycles ships (empty from older bridges and from builds
    /// without CUDA).
    #[serde(default)]
    pub cuda_kernels: crate::device::CudaKernels,
    /// What this build offers beyond 3.4's Cycles.
    #[serde(default)]
    pub features: Features,
    /// The settings the bridge changes on this version to render as 3.4 does
    /// (`compat.parity_settings()`: switch name to value, e.g. `{"coat": true}` on 4.x;
    /// empty on 3.x and from older bridges).
    #[serde(default)]
    pub compat: BTreeMap<String, serde_json::Value>,
    /// Anything else the bridge reported.
    #[serde(flatten)]
    pub extra: BTreeMap<String, serde_json::Value>,
}

impl Ready {
    /// For `doctor`: one line per NVIDIA GPU (named by `caps`, see
    /// [`crate::device::nvidia_compute_capabilities`]) on whether this Blender ships its CUDA
    /// kernel or has the driver compile one at the first render; none without such GPUs.
    pub fn cuda_kernel_lines(&self, caps: &[(String, u32)]) -> Vec<String> {
        use crate::device::KernelLoad;
        let mut seen = std::collections::BTreeSet::new();
        crate::device::kernel_loads(&self.gpus, &self.cuda_kernels, caps)
            .into_iter()
            .filter(|(g, _, _)| seen.insert(g.name.clone()))
            .map(|(g, cc, load)| {
                let what = match load {
                    KernelLoad::Shipped => format!("shipped (sm_{cc}): nothing to compile"),
                    KernelLoad::Prepared => format!(
                        "prepared (sm_{cc}, compiled ahead of time by `scripts/cuda_kernels.py`): nothing to compile"
                    ),
                    KernelLoad::Compiled { from } => format!(
                        "will be compiled: none for sm_{cc}, so the driver compiles PTX compute_{from} at each worker's first render unless its cache holds it (many minutes; prepare it once with `./scripts/setup.sh --bpy 4.5 --cuda-arch {cc}`)"
                    ),
                    KernelLoad::Missing => format!("none for sm_{cc} and no PTX: Cycles cannot use it"),
                };
                format!(
                    "cuda kernel for `{}` ({}.{}): {what}; this Blender ships {}",
                    g.name,
                    cc / 10,
                    cc % 10,
                    self.cuda_kernels.describe()
                )
            })
            .collect()
    }

    /// `gpus: ...; oidn: yes; path guiding: yes; light tree: yes`, for `doctor`.
    pub fn features_line(&self) -> String {
        let gpus: Vec<String> = self
            .gpus
            .iter()
            .map(|g| format!("{} `{}`", g.kind, g.name))
            .collect();
        let yes_no = |b: bool| if b { "yes" } else { "no" };
        let f = &self.features;
        format!(
            "gpus: {}; oidn: {}; path guiding: {}; light tree: {}",
            if gpus.is_empty() {
                "none".to_string()
            } else {
                gpus.join(", ")
            },
            yes_no(f.oidn),
            yes_no(f.path_guiding),
            yes_no(f.light_tree)
        )
    }
}

/// Optional Cycles features of a Blender build (`features` of the `ready` reply).
#[derive(Debug, Clone, Default, Deserialize)]
pub struct Features {
    /// OpenImageDenoise compiled in.
    #[serde(default)]
    pub oidn: bool,
    /// Path guiding compiled in (CPU rendering only).
    #[serde(default)]
    pub path_guiding: bool,
    /// The light tree setting exists (4.0+).
    #[serde(default)]
    pub light_tree: bool,
    /// Names of the sampling patterns offered.
    #[serde(default)]
    pub sampling_patterns: Vec<String>,
}

/// Render mode of a request.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Mode {
    /// Cheap check: 1 sample, no displacement, only the object-index pass.
    Visibility,
    /// Full settings from the scene file.
    Final,
}

impl Mode {
    /// The protocol name.
    pub fn name(self) -> &'static str {
        match self {
            Mode::Visibility => "visibility",
            Mode::Final => "final",
        }
    }
}

/// Timings the bridge reports for one request, in seconds.
#[derive(Debug, Clone, Copy, Default, Deserialize)]
pub struct BridgeTimings {
    /// Building (or updating) the Blender scene; 0 when the build was reused.
    #[serde(default)]
    pub build_s: f64,
    /// Cycles rendering.
    #[serde(default)]
    pub render_s: f64,
    /// CPU seconds of the whole Blender process (all threads) during the final render (not
    /// the shadow pass's); `None` from bridges older than this field and for visibility renders.
    #[serde(default)]
    pub render_cpu_s: Option<f64>,
    /// Writing the output files.
    #[serde(default)]
    pub write_s: f64,
    /// The shadow pass's two direct-light renders, together (0 without the pass).
    #[serde(default)]
    pub shadow_render_s: f64,
}

/// The reply to a `render` request.
#[derive(Debug, Clone, Deserialize)]
pub struct RenderReply {
    /// Files written, by role (`visibility`, `rgb`, `passes`, `shadow`).
    #[serde(default)]
    pub files: BTreeMap<String, PathBuf>,
    /// Where the time went.
    #[serde(default)]
    pub timings: BridgeTimings,
    /// Each object's origin projected by Blender's camera: `[x, y, depth]`, pixels, y down.
    #[serde(default)]
    pub projected: Vec<[f64; 3]>,
}

impl RenderReply {
    /// A file the bridge says it wrote, which must lie in our scratch folder `work`.
    pub(crate) fn file(&self, role: &str, work: &Path) -> Result<PathBuf> {
        let path = self.files.get(role).ok_or_else(|| RenderError::BadOutput {
            path: work.to_path_buf(),
            problem: format!(
                "the bridge reported no `{role}` file (got: {})",
                self.files.keys().cloned().collect::<Vec<_>>().join(", ")
            ),
        })?;
        // Blender's output is not trusted (docs/security.md): a reply naming a file elsewhere
        // (`/home/me/secret`, `work/../x`, a link out of `work`) would have it read and copied
        // into the dataset.
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
}

/// What a `material` request renders around the material (see
/// `blender_scripts/material_tool.py`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum MaterialMode {
    /// A sphere and a cube on a grey floor, labelled (the contact sheet).
    Sheet,
    /// A flat-lit square seen straight down (distinctness statistics).
    Tile,
    /// Like `Sheet`, plus the share of pink (missing-texture) pixels (`pink`).
    Check,
    /// A sphere filling the frame, timed.
    Cost,
    /// A small and a large cube side by side, orthographic, plus their stripe periods
    /// (`period_small`, `period_large`, `flips_small`, `flips_large`).
    Density,
}

impl MaterialMode {
    /// The protocol name.
    pub fn name(self) -> &'static str {
        match self {
            MaterialMode::Sheet => "sheet",
            MaterialMode::Tile => "tile",
            MaterialMode::Check => "check",
            MaterialMode::Cost => "cost",
            MaterialMode::Density => "density",
        }
    }
}

/// The settings of a `material` request, shared by every material of a batch.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MaterialSettings {
    /// What to render.
    pub mode: MaterialMode,
    /// Image width in pixels (the height follows from the mode).
    pub size: u32,
    /// Samples per pixel.
    pub samples: u32,
    /// Displacement strength given to the instance (0: none).
    pub displacement: f64,
    /// The instance's `random` value (0.37 unless comparing instances).
    pub random: f64,
}

/// The reply to a `material` request.
#[derive(Debug, Clone, Deserialize)]
pub struct MaterialReply {
    /// The PNG written (`<out_dir>/<name>.png`).
    pub file: PathBuf,
    /// Scene build and Cycles time.
    #[serde(default)]
    pub timings: BridgeTimings,
    /// What the mode measures on the image (`pink` for check, stripe periods for density).
    #[serde(default)]
    pub measures: BTreeMap<String, f64>,
}

/// One socket of a user node group (the reply to `inspect`).
#[derive(Debug, Clone, Deserialize)]
pub struct GroupSocket {
    /// Socket name.
    pub name: String,
    /// Blender's socket type (`VALUE`, `RGBA`, `SHADER`, ... or `NodeSocket*` in 4.x).
    #[serde(default)]
    pub r#type: String,
}

/// One image a user node group reads (the reply to `inspect`).
#[derive(Debug, Clone, Deserialize)]
pub struct GroupImage {
    /// Blender's image name.
    pub name: String,
    /// The file, as Blender resolves it (absolute; relative to the `.blend` before).
    pub path: String,
    /// Blender's image source: `FILE`, `GENERATED`, `SEQUENCE`, `TILED`, ...
    pub source: String,
    /// Packed into the `.blend` (then no file is read).
    pub packed: bool,
}

/// The reply to an `inspect` request: a user `.blend` material's node group as the bridge
/// loads it, for the checks before a run (nothing rendered, no pixels loaded).
#[derive(Debug, Clone, Deserialize)]
pub struct InspectReply {
    /// The node group used.
    pub group: String,
    /// Its inputs.
    pub inputs: Vec<GroupSocket>,
    /// Its outputs.
    pub outputs: Vec<GroupSocket>,
    /// Every image an image-texture node of it (or of a group inside it) reads.
    pub images: Vec<GroupImage>,
}

enum Event {
    Reply(String),
    Eof,
}

/// A running Blender worker. Dropping it kills the process.
#[derive(Debug)]
pub struct Worker {
    program: PathBuf,
    child: Child,
    stdin: Option<ChildStdin>,
    events: Receiver<Event>,
    tag: String,
    tails: Arc<Mutex<(VecDeque<String>, VecDeque<String>)>>,
    next_id: u64,
    ready: Ready,
    startup: Duration,
    interrupt: Arc<AtomicBool>,
    dead: bool,
    streams_closed: Arc<AtomicBool>,
    /// Milliseconds after `epoch` of the last line Blender printed (on either stream).
    activity: Arc<AtomicU64>,
    epoch: Instant,
    idle_timeout: Option<Duration>,
    /// Blender's `TMPDIR`: removed when the worker is dropped, after `Drop` killed Blender.
    _tmp: tempfile::TempDir,
}

impl std::fmt::Debug for Event {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Event::Reply(r) => write!(f, "Reply({r})"),
            Event::Eof => f.write_str("Eof"),
        }
    }
}

/// A fresh tag such as `@@clevrtex-0123456789abcdef@@`. Not data, so not seeded: it only
/// has to be unguessable by Blender's chatter.
fn fresh_tag() -> String {
    let mut h = std::collections::hash_map::RandomState::new().build_hasher();
    h.write_u128(
        std::time::SystemTime::now()
            .duration_since(std::time::UNIX_EPOCH)
            .map(|d| d.as_nanos())
            .unwrap_or(0),
    );
    h.write_u32(std::process::id());
    format!("@@clevrtex-{:016x}@@", h.finish())
}

impl Worker {
    /// Start Blender with the bridge and wait for its `ready` message.
    pub fn start(opts: &WorkerOptions) -> Result<Worker> {
        let started = Instant::now();
        let tag = fresh_tag();
        let flavour = crate::blender::flavour(&opts.blender);
        let bridge_args: Vec<std::ffi::OsString> = vec![
            "--tag".into(),
            tag.clone().into(),
            "--threads".into(),
            opts.threads.to_string().into(),
            "--materials".into(),
            opts.materials.clone().into_os_string(),
            "--device".into(),
            opts.device.arg().into(),
        ];
        let mut cmd =
            crate::blender::worker_command(&opts.blender, flavour, &opts.script, &bridge_args);
        cmd.stdin(Stdio::piped())
            .stdout(Stdio::piped())
            .stderr(Stdio::piped());
        // Blender's own temporary files (`blender_*` folders, left behind whenever a worker is
        // killed) go into a private folder removed with the worker, or by the next run if we
        // are killed ourselves.
        let tmp = crate::tmp::private_dir("clevrtex-blender-")?;
        cmd.env("TMPDIR", tmp.path());
        // The bridge asks the kernel to kill it when we die, even by SIGKILL, and checks that
        // we are still its parent (see worker.py).
        cmd.env("CLEVRTEX_PARENT_PID", std::process::id().to_string());
        // On a GPU, let the driver keep a compiled Cycles kernel (up to CUDA's 4 GiB maximum;
        // its default is smaller than the kernel), so only a machine's first run compiles it
        // (`device::kernel_compile_warning`). A value the user set wins.
        if opts.device.is_gpu() && std::env::var_os("CUDA_CACHE_MAXSIZE").is_none() {
            cmd.env("CUDA_CACHE_MAXSIZE", "4294967296");
        }
        // Own process group: a Ctrl-C in the terminal reaches only us, and a kill reaches a
        // wrapper script's Blender too (`group`).
        crate::group::own_group(&mut cmd);
        let mut child = cmd.spawn().map_err(|source| {
            if source.kind() == std::io::ErrorKind::NotFound {
                RenderError::BlenderNotFound {
                    tried: Some(opts.blender.clone()),
                }
            } else {
                RenderError::Spawn {
                    program: opts.blender.clone(),
                    cause: source,
                }
            }
        })?;
        let tails = Arc::new(Mutex::new((VecDeque::new(), VecDeque::new())));
        let epoch = Instant::now();
        let activity = Arc::new(AtomicU64::new(0));
        let touch = {
            let activity = Arc::clone(&activity);
            move || activity.store(epoch.elapsed().as_millis() as u64, Ordering::Relaxed)
        };
        let (tx, events) = mpsc::sync_channel(MAX_PENDING_REPLIES);
        let stdout = child.stdout.take().expect("piped");
        let stderr = child.stderr.take().expect("piped");
        {
            let tails = Arc::clone(&tails);
            let prefix = format!("{tag} ");
            let touch = touch.clone();
            std::thread::spawn(move || {
                read_lines(stdout, |line| {
                    touch();
                    if let Some(rest) = line.strip_prefix(&prefix) {
                        let _ = tx.send(Event::Reply(rest.to_string()));
                    } else if line.starts_with(prefix.trim_end()) {
                        let _ = tx.send(Event::Reply(String::new()));
                    } else {
                        push_tail(&mut tails.lock().unwrap().0, line);
                    }
                });
                let _ = tx.send(Event::Eof);
            });
        }
        let streams_closed = Arc::new(AtomicBool::new(false));
        {
            let tails = Arc::clone(&tails);
            let closed = Arc::clone(&streams_closed);
            std::thread::spawn(move || {
                read_lines(stderr, |line| {
                    touch();
                    push_tail(&mut tails.lock().unwrap().1, line)
                });
                closed.store(true, Ordering::SeqCst);
            });
        }
        let stdin = child.stdin.take();
        let mut worker = Worker {
            program: opts.blender.clone(),
            child,
            stdin,
            events,
            tag,
            tails,
            next_id: 1,
            ready: Ready {
                bridge_version: 0,
                blender_version: String::new(),
                cycles_devices: Vec::new(),
                gpus: Vec::new(),
                cuda_kernels: Default::default(),
                features: Features::default(),
                compat: BTreeMap::new(),
                extra: BTreeMap::new(),
            },
            startup: Duration::ZERO,
            interrupt: Arc::clone(&opts.interrupt),
            dead: false,
            streams_closed,
            activity,
            epoch,
            idle_timeout: None,
            _tmp: tmp,
        };
        let doing = crate::error::STARTING_UP.to_string();
        let reply = worker.wait_reply(Instant::now() + opts.startup_timeout, &doing)?;
        let ready: Ready = worker.expect_type(&reply, "ready", &doing)?;
        if ready.bridge_version != crate::bridge::BRIDGE_VERSION {
            let line = reply.to_string();
            return Err(worker.fail_protocol(
                &doing,
                line,
                format!(
                    "bridge protocol version {} but this binary speaks {}",
                    ready.bridge_version,
                    crate::bridge::BRIDGE_VERSION
                ),
            ));
        }
        worker.ready = ready;
        worker.startup = started.elapsed();
        Ok(worker)
    }

    /// Also give up on a request when Blender prints nothing at all for `idle` (Cycles
    /// prints a line per sample, so a silent worker is hung even if the request's overall
    /// time limit is far away). `None` (the default) checks only the overall limit.
    pub fn set_idle_timeout(&mut self, idle: Option<Duration>) {
        self.idle_timeout = idle;
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
        self.dead
    }

    /// Ask the worker to render `scene` (a scene file path) in `mode` into `out_dir`, and
    /// wait at most `timeout` for the reply. On timeout, crash or garbage the worker is
    /// killed (see [`Worker::is_dead`]); a [`RenderError::Bridge`] error leaves it usable.
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
        let request = serde_json::json!({
            "type": "render",
            "mode": mode.name(),
            "scene": scene,
            "out_dir": out_dir,
        });
        self.call(request, &doing, timeout)
    }

    /// Ask the worker to render material `name` of its catalogue on the small scene of
    /// `settings.mode`, into `out_dir/<name>.png` (`out_dir` must exist), and wait at most
    /// `timeout`. Failures as for [`Worker::render`]: a material that does not build is a
    /// [`RenderError::Bridge`] error and leaves the worker usable; a reply naming any other
    /// file than `out_dir/<name>.png`, or not a regular file, is a [`RenderError::Protocol`]
    /// error.
    pub fn material(
        &mut self,
        settings: &MaterialSettings,
        name: &str,
        out_dir: &Path,
        timeout: Duration,
    ) -> Result<MaterialReply> {
        let doing = format!("rendering material `{name}` ({})", settings.mode.name());
        let request = serde_json::json!({
            "type": "material",
            "mode": settings.mode.name(),
            "name": name,
            "out_dir": out_dir,
            "size": settings.size,
            "samples": settings.samples,
            "displacement": settings.displacement,
            "random": settings.random,
        });
        let reply: MaterialReply = self.call(request, &doing, timeout)?;
        // Blender's output is not trusted (docs/security.md): the file named must be the one
        // asked for, since callers read it and move it into their cache.
        let expected = out_dir.join(format!("{name}.png"));
        let regular = std::fs::symlink_metadata(&reply.file).is_ok_and(|m| m.is_file());
        if reply.file != expected || !regular {
            let line = reply.file.display().to_string();
            let problem = if reply.file != expected {
                format!("the reply names another file than `{}`", expected.display())
            } else {
                format!("`{}` is not a regular file", expected.display())
            };
            return Err(self.fail_protocol(&doing, line, problem));
        }
        Ok(reply)
    }

    /// Ask the worker which node group of the `.blend` at `path` it would use (`group`, or
    /// the file's own as the public generator names it), with its sockets and textures.
    /// A `.blend` without a usable group is a [`RenderError::Bridge`] error.
    pub fn inspect(
        &mut self,
        path: &Path,
        group: Option<&str>,
        timeout: Duration,
    ) -> Result<InspectReply> {
        let doing = format!("inspecting the user material `{}`", path.display());
        let request = serde_json::json!({"type": "inspect", "path": path, "group": group});
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
        self.send(&request, doing)?;
        let reply = self.wait_reply(Instant::now() + timeout, doing)?;
        if reply.get("id").and_then(|v| v.as_u64()) != Some(id) {
            let line = reply.to_string();
            return Err(self.fail_protocol(
                doing,
                line,
                format!("expected a reply to request {id}"),
            ));
        }
        self.expect_type(&reply, "done", doing)
    }

    /// Ask the worker to quit and wait briefly for it; kills it if it lingers.
    pub fn quit(mut self) {
        let _ = self.send(&serde_json::json!({"type": "quit"}), "quitting");
        self.stdin = None;
        let deadline = Instant::now() + Duration::from_secs(5);
        while Instant::now() < deadline {
            if let Ok(Some(_)) = self.child.try_wait() {
                self.dead = true;
                return;
            }
            std::thread::sleep(POLL);
        }
        self.kill();
    }

    /// Current output tails. After the process died, waits briefly for its last stderr
    /// lines (the reader thread may still be draining the pipe).
    pub fn tails(&self) -> Tails {
        if self.dead {
            let deadline = Instant::now() + Duration::from_secs(1);
            while !self.streams_closed.load(Ordering::SeqCst) && Instant::now() < deadline {
                std::thread::sleep(Duration::from_millis(10));
            }
        }
        let t = self.tails.lock().unwrap();
        Tails {
            stdout: t.0.iter().cloned().collect(),
            stderr: t.1.iter().cloned().collect(),
        }
    }

    fn send(&mut self, msg: &serde_json::Value, doing: &str) -> Result<()> {
        let mut line = msg.to_string();
        line.push('\n');
        let ok = match self.stdin.as_mut() {
            Some(stdin) => stdin
                .write_all(line.as_bytes())
                .and_then(|_| stdin.flush())
                .is_ok(),
            None => false,
        };
        if ok {
            return Ok(());
        }
        // A broken pipe means the process died: report it with its status and tails.
        let status = self.wait_exit(EXIT_GRACE);
        Err(RenderError::Exited {
            program: self.program.clone(),
            doing: doing.to_string(),
            status,
            tails: Box::new(self.tails()),
        })
    }

    fn expect_type<T: serde::de::DeserializeOwned>(
        &mut self,
        reply: &serde_json::Value,
        expected: &str,
        doing: &str,
    ) -> Result<T> {
        match reply.get("type").and_then(|t| t.as_str()) {
            Some(t) if t == expected => serde_json::from_value(reply.clone()).map_err(|e| {
                self.fail_protocol(
                    doing,
                    reply.to_string(),
                    format!("bad `{expected}` reply: {e}"),
                )
            }),
            Some("error") => Err(RenderError::Bridge {
                doing: doing.to_string(),
                message: reply
                    .get("message")
                    .and_then(|m| m.as_str())
                    .unwrap_or("(no message)")
                    .to_string(),
                traceback: reply
                    .get("traceback")
                    .and_then(|m| m.as_str())
                    .map(|t| format!("{}\n", t.trim_end()))
                    .unwrap_or_default(),
            }),
            _ => Err(self.fail_protocol(
                doing,
                reply.to_string(),
                format!("expected a `{expected}` reply"),
            )),
        }
    }

    fn fail_protocol(&mut self, doing: &str, mut line: String, problem: String) -> RenderError {
        self.kill();
        if line.len() > 200 {
            let mut cut = 200;
            while !line.is_char_boundary(cut) {
                cut -= 1;
            }
            line.truncate(cut);
            line.push_str("...");
        }
        RenderError::Protocol {
            program: self.program.clone(),
            doing: doing.to_string(),
            line,
            problem,
            tails: Box::new(self.tails()),
        }
    }

    /// Wait for the next reply line until `deadline`, watching for exit and interrupts.
    fn wait_reply(&mut self, deadline: Instant, doing: &str) -> Result<serde_json::Value> {
        let waited = Instant::now();
        loop {
            if self.interrupt.load(Ordering::SeqCst) {
                self.kill();
                return Err(RenderError::Interrupted);
            }
            let now = Instant::now();
            let last = self.epoch + Duration::from_millis(self.activity.load(Ordering::Relaxed));
            let idle = now.saturating_duration_since(last.max(waited));
            if let Some(limit) = self.idle_timeout.filter(|l| idle >= *l) {
                self.kill();
                return Err(RenderError::Timeout {
                    program: self.program.clone(),
                    doing: format!(
                        "{doing}, silent for {:.0} s (idle limit {:.0} s)",
                        idle.as_secs_f64(),
                        limit.as_secs_f64()
                    ),
                    after: waited.elapsed(),
                    tails: Box::new(self.tails()),
                });
            }
            if now >= deadline {
                self.kill();
                return Err(RenderError::Timeout {
                    program: self.program.clone(),
                    doing: doing.to_string(),
                    after: waited.elapsed(),
                    tails: Box::new(self.tails()),
                });
            }
            match self.events.recv_timeout(POLL.min(deadline - now)) {
                Ok(Event::Reply(text)) => {
                    return match serde_json::from_str::<serde_json::Value>(&text) {
                        Ok(v) if v.is_object() => Ok(v),
                        Ok(_) => Err(self.fail_protocol(doing, text, "not a JSON object".into())),
                        Err(e) => Err(self.fail_protocol(doing, text, format!("not JSON: {e}"))),
                    };
                }
                Ok(Event::Eof) | Err(RecvTimeoutError::Disconnected) => {
                    let status = self.wait_exit(EXIT_GRACE);
                    return Err(RenderError::Exited {
                        program: self.program.clone(),
                        doing: doing.to_string(),
                        status,
                        tails: Box::new(self.tails()),
                    });
                }
                Err(RecvTimeoutError::Timeout) => {}
            }
        }
    }

    /// Wait up to `grace` for the process to exit (killing it after), returning its status.
    fn wait_exit(&mut self, grace: Duration) -> Option<std::process::ExitStatus> {
        self.dead = true;
        self.stdin = None;
        let deadline = Instant::now() + grace;
        loop {
            match self.child.try_wait() {
                Ok(Some(status)) => return Some(status),
                Ok(None) if Instant::now() < deadline => std::thread::sleep(POLL),
                _ => {
                    self.kill();
                    return None;
                }
            }
        }
    }

    /// Kill the process and its whole process group (a wrapper's Blender, anything Blender
    /// started), and reap it (idempotent).
    fn kill(&mut self) {
        self.dead = true;
        self.stdin = None;
        crate::group::kill_group(&mut self.child);
    }
}

impl Drop for Worker {
    fn drop(&mut self) {
        self.kill();
    }
}

fn push_tail(tail: &mut VecDeque<String>, line: &str) {
    if tail.len() == TAIL_LINES {
        tail.pop_front();
    }
    let mut end = line.len().min(MAX_TAIL_LINE);
    while !line.is_char_boundary(end) {
        end -= 1;
    }
    if end < line.len() {
        tail.push_back(format!(
            "{} [... {} more bytes]",
            &line[..end],
            line.len() - end
        ));
    } else {
        tail.push_back(line.to_string());
    }
}

/// Call `f` on each line (lossy UTF-8, without the line ending) until EOF or a read error.
///
/// Blender's output is not trusted: a line longer than [`MAX_LINE`] bytes is cut there (the
/// rest of it is read and dropped, never buffered), so output without a newline costs at
/// most that much memory; a cut reply is then not valid JSON and ends as a protocol error.
fn read_lines(stream: impl Read, mut f: impl FnMut(&str)) {
    let mut reader = BufReader::new(stream);
    let mut buf = Vec::new();
    loop {
        buf.clear();
        let mut cut = false;
        let ended = loop {
            let chunk = match reader.fill_buf() {
                Ok([]) | Err(_) => break false,
                Ok(chunk) => chunk,
            };
            let (take, newline) = match chunk.iter().position(|&b| b == b'\n') {
                Some(i) => (i + 1, true),
                None => (chunk.len(), false),
            };
            let room = MAX_LINE.saturating_sub(buf.len());
            cut |= take > room;
            buf.extend_from_slice(&chunk[..take.min(room)]);
            reader.consume(take);
            if newline {
                break true;
            }
        };
        if buf.is_empty() && !ended {
            return;
        }
        let text = String::from_utf8_lossy(&buf);
        let line = text.trim_end_matches(['\n', '\r']);
        if cut {
            f(&format!("{line} [line cut at {MAX_LINE} bytes]"));
        } else {
            f(line);
        }
        if !ended {
            return;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// `doctor`'s line per NVIDIA GPU: shipped, prepared (`scripts/cuda_kernels.py`) or will
    /// be compiled, as the bridge's `ready` reports the kernels.
    #[test]
    fn doctor_says_per_gpu_whether_its_kernel_is_shipped_prepared_or_compiled() {
        let ready: Ready = serde_json::from_str(
            r#"{"type": "ready", "bridge_version": 1, "blender_version": "4.5.3",
                "cycles_devices": ["CPU", "CUDA"],
                "gpus": [{"kind": "CUDA", "name": "H100"}, {"kind": "CUDA", "name": "A100"},
                         {"kind": "CUDA", "name": "L4"}],
                "cuda_kernels": {"cubin": [75, 89, 90], "ptx": [75], "prepared": [90]}}"#,
        )
        .unwrap();
        let caps = [
            ("H100".to_string(), 90),
            ("A100".to_string(), 80),
            ("L4".to_string(), 89),
        ];
        let lines = ready.cuda_kernel_lines(&caps);
        assert_eq!(lines.len(), 3, "{lines:?}");
        assert!(
            lines[0].contains("`H100` (9.0): prepared (sm_90"),
            "{}",
            lines[0]
        );
        assert!(
            lines[1].contains("`A100` (8.0): will be compiled: none for sm_80")
                && lines[1].contains("--cuda-arch 80"),
            "{}",
            lines[1]
        );
        assert!(
            lines[2].contains("`L4` (8.9): shipped (sm_89)"),
            "{}",
            lines[2]
        );
    }
}
