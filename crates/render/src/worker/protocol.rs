//! The bridge protocol's messages (`docs/bridge-protocol.md`): the tag that marks replies,
//! the requests we send, the replies we accept (each checked before use: Blender's output is
//! not trusted, docs/security.md) and the feature negotiation of the `ready` reply.

use std::collections::BTreeMap;
use std::hash::{BuildHasher, Hasher};
use std::path::{Path, PathBuf};

use serde::de::DeserializeOwned;
use serde::Deserialize;

use crate::error::{RenderError, Result};

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
    /// Where the request's time went, phase by phase (zero from bridges older than this
    /// field).
    #[serde(default)]
    pub phases: BridgePhases,
}

/// Wall and CPU seconds of one phase of a request.
#[derive(Debug, Clone, Copy, Default, PartialEq, Deserialize)]
pub struct PhaseTime {
    /// Wall-clock seconds.
    #[serde(default)]
    pub wall_s: f64,
    /// CPU seconds of the whole Blender process (all threads).
    #[serde(default)]
    pub cpu_s: f64,
}

impl PhaseTime {
    fn add(&mut self, other: &PhaseTime) {
        self.wall_s += other.wall_s;
        self.cpu_s += other.cpu_s;
    }
}

/// The phases of a request as the bridge reports them (`blender_scripts/phases.py`; the
/// render calls split by the Cycles status line in effect). Their sum is the request's time
/// in the bridge.
#[derive(Debug, Clone, Copy, Default, PartialEq, Deserialize)]
pub struct BridgePhases {
    /// Building the Blender scene from the scene file (0 when reused).
    #[serde(default)]
    pub build: PhaseTime,
    /// Building and assigning the materials' node trees.
    #[serde(default)]
    pub materials: PhaseTime,
    /// Render start: depsgraph, Cycles session, scene sync (objects, shaders, images).
    #[serde(default)]
    pub sync: PhaseTime,
    /// True displacement: tessellating and displacing.
    #[serde(default)]
    pub displacement: PhaseTime,
    /// Building the BVH.
    #[serde(default)]
    pub bvh: PhaseTime,
    /// Path tracing.
    #[serde(default)]
    pub path_tracing: PhaseTime,
    /// Denoising.
    #[serde(default)]
    pub denoise: PhaseTime,
    /// Writing the output files.
    #[serde(default)]
    pub write: PhaseTime,
    /// Anything else (result readback, statuses Cycles adds later).
    #[serde(default)]
    pub other: PhaseTime,
}

impl BridgePhases {
    /// Every phase with its name, in request order.
    pub fn named(&self) -> [(&'static str, PhaseTime); 9] {
        [
            ("build", self.build),
            ("materials", self.materials),
            ("sync", self.sync),
            ("displacement", self.displacement),
            ("bvh", self.bvh),
            ("path_tracing", self.path_tracing),
            ("denoise", self.denoise),
            ("write", self.write),
            ("other", self.other),
        ]
    }

    /// Adds `other`'s phases to these.
    pub fn add(&mut self, other: &BridgePhases) {
        let pairs = [
            (&mut self.build, &other.build),
            (&mut self.materials, &other.materials),
            (&mut self.sync, &other.sync),
            (&mut self.displacement, &other.displacement),
            (&mut self.bvh, &other.bvh),
            (&mut self.path_tracing, &other.path_tracing),
            (&mut self.denoise, &other.denoise),
            (&mut self.write, &other.write),
            (&mut self.other, &other.other),
        ];
        for (a, b) in pairs {
            a.add(b);
        }
    }

    /// Total CPU seconds over every phase.
    pub fn cpu_s(&self) -> f64 {
        self.named().iter().map(|(_, p)| p.cpu_s).sum()
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

impl Features {
    /// Why a scene with these render settings cannot be rendered as asked on this build
    /// (`None`: it can): `denoise` (the `fast` quality preset) on a build without
    /// OpenImageDenoise (Debian's Blender 3.4) would give noisy images, not denoised ones.
    pub fn refusal(
        &self,
        render: &clevrtex_scene::scene_file::RenderSettings,
        blender_version: &str,
    ) -> Option<String> {
        (render.denoise && !self.oidn).then(|| {
            format!(
                "the scene asks for OpenImageDenoise (`render.denoise`, set by `--quality fast`), \
                 which this Blender ({blender_version}) lacks: its images would be noisy, not \
                 denoised\nhint: render it with a Blender 4.x that has OIDN (e.g. `--blender \
                 .venv-bpy/bin/python`, PyPI's bpy 4.5; `clevrtex doctor` says `oidn: yes`), or \
                 leave denoising out (`--quality draft`, or the default 64 samples)"
            )
        })
    }
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
    /// A packed image: the file the bridge wrote its bytes to (in the `packed_dir` of the
    /// request), to be checked like any texture file.
    #[serde(default)]
    pub file: Option<String>,
    /// A packed image: its key in the recipe's `images` (`packed:<n>`).
    #[serde(default)]
    pub key: Option<String>,
    /// A generated image: its size in pixels (from its settings; no pixels made).
    #[serde(default)]
    pub width: u32,
    /// See `width`.
    #[serde(default)]
    pub height: u32,
}

/// The reply to an `inspect` request: a user `.blend` material's node group as the bridge
/// loads it, for the checks before a run (nothing rendered, no pixels loaded).
#[derive(Debug, Clone, Deserialize)]
pub struct InspectReply {
    /// The node group used, by its name in the file (the name it has once loaded may carry
    /// a `.001` when another file's group has the same name).
    pub group: String,
    /// Its inputs.
    pub inputs: Vec<GroupSocket>,
    /// Its outputs.
    pub outputs: Vec<GroupSocket>,
    /// Every image an image-texture node of it (or of a group inside it) reads.
    pub images: Vec<GroupImage>,
}

/// A fresh tag such as `@@clevrtex-0123456789abcdef@@`. Not data, so not seeded: it only
/// has to be unguessable by Blender's chatter.
pub(super) fn fresh_tag() -> String {
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

/// The arguments of the bridge's command line: replies marked by `tag`, `threads` Cycles
/// threads, the catalogue `materials`, rendering on `device`.
pub(super) fn bridge_args(
    tag: &str,
    threads: u32,
    materials: &Path,
    device: &crate::device::Placement,
) -> Vec<std::ffi::OsString> {
    vec![
        "--tag".into(),
        tag.into(),
        "--threads".into(),
        threads.to_string().into(),
        "--materials".into(),
        materials.as_os_str().to_os_string(),
        "--device".into(),
        device.arg().into(),
    ]
}

/// A `render` request of `scene` in `mode` into `out_dir` (its `id` is added when sent).
pub(super) fn render_request(mode: Mode, scene: &Path, out_dir: &Path) -> serde_json::Value {
    serde_json::json!({
        "type": "render",
        "mode": mode.name(),
        "scene": scene,
        "out_dir": out_dir,
    })
}

/// A `material` request of material `name` with `settings` into `out_dir`.
pub(super) fn material_request(
    settings: &MaterialSettings,
    name: &str,
    out_dir: &Path,
) -> serde_json::Value {
    serde_json::json!({
        "type": "material",
        "mode": settings.mode.name(),
        "name": name,
        "out_dir": out_dir,
        "size": settings.size,
        "samples": settings.samples,
        "displacement": settings.displacement,
        "random": settings.random,
    })
}

/// An `inspect` request of the `.blend` at `path` (its node group `group`, else the file's
/// own); the bytes of its packed images are written into `packed_dir`.
pub(super) fn inspect_request(
    path: &Path,
    group: Option<&str>,
    packed_dir: Option<&Path>,
) -> serde_json::Value {
    serde_json::json!({"type": "inspect", "path": path, "group": group, "packed_dir": packed_dir})
}

/// The `quit` request.
pub(super) fn quit_request() -> serde_json::Value {
    serde_json::json!({"type": "quit"})
}

/// A reply line (without its tag) as the JSON object every reply is, or what is wrong.
pub(super) fn parse_line(text: &str) -> std::result::Result<serde_json::Value, String> {
    match serde_json::from_str::<serde_json::Value>(text) {
        Ok(v) if v.is_object() => Ok(v),
        Ok(_) => Err("not a JSON object".into()),
        Err(e) => Err(format!("not JSON: {e}")),
    }
}

/// Whether `reply` answers request `id`; what is wrong if not.
pub(super) fn check_id(reply: &serde_json::Value, id: u64) -> std::result::Result<(), String> {
    match reply.get("id").and_then(|v| v.as_u64()) == Some(id) {
        true => Ok(()),
        false => Err(format!("expected a reply to request {id}")),
    }
}

/// Why a reply is not the one expected.
pub(super) enum Unexpected {
    /// The bridge's `error` reply: the request failed, the worker stays usable.
    Failed(RenderError),
    /// Anything else (what is wrong): the worker is out of step.
    Garbled(String),
}

/// `reply` as the `expected` reply type `T`.
pub(super) fn expect_type<T: DeserializeOwned>(
    reply: &serde_json::Value,
    expected: &str,
    doing: &str,
) -> std::result::Result<T, Unexpected> {
    match reply.get("type").and_then(|t| t.as_str()) {
        Some(t) if t == expected => serde_json::from_value(reply.clone())
            .map_err(|e| Unexpected::Garbled(format!("bad `{expected}` reply: {e}"))),
        Some("error") => Err(Unexpected::Failed(RenderError::Bridge {
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
        })),
        _ => Err(Unexpected::Garbled(format!(
            "expected a `{expected}` reply"
        ))),
    }
}

/// Whether the bridge that sent `ready` speaks this binary's protocol version; what is wrong
/// if not.
pub(super) fn check_version(ready: &Ready) -> std::result::Result<(), String> {
    if ready.bridge_version != crate::bridge::BRIDGE_VERSION {
        return Err(format!(
            "bridge protocol version {} but this binary speaks {}",
            ready.bridge_version,
            crate::bridge::BRIDGE_VERSION
        ));
    }
    Ok(())
}

/// Whether a `material` reply names the file asked for, `<out_dir>/<name>.png`, and it is a
/// regular file: callers read it and move it into their cache. What is wrong if not.
pub(super) fn check_material_file(
    reply: &MaterialReply,
    name: &str,
    out_dir: &Path,
) -> std::result::Result<(), String> {
    let expected = out_dir.join(format!("{name}.png"));
    let regular = std::fs::symlink_metadata(&reply.file).is_ok_and(|m| m.is_file());
    if reply.file != expected || !regular {
        return Err(if reply.file != expected {
            format!("the reply names another file than `{}`", expected.display())
        } else {
            format!("`{}` is not a regular file", expected.display())
        });
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The bridge reports only the phases that took time; the rest read as zero, an older
    /// bridge's reply (no `phases`) too, and a run's sums add phase by phase.
    #[test]
    fn phases_read_partial_replies_and_add_up() {
        let t: BridgeTimings = serde_json::from_str(
            r#"{"render_s": 1.0, "phases": {"sync": {"wall_s": 0.5, "cpu_s": 0.25},
                "path_tracing": {"wall_s": 2.0, "cpu_s": 1.5}, "future": {"wall_s": 9.0}}}"#,
        )
        .unwrap();
        assert_eq!(t.phases.sync.cpu_s, 0.25);
        assert_eq!(t.phases.displacement, PhaseTime::default());
        let old: BridgeTimings = serde_json::from_str(r#"{"render_s": 1.0}"#).unwrap();
        assert_eq!(old.phases, BridgePhases::default());
        let mut sum = BridgePhases::default();
        sum.add(&t.phases);
        sum.add(&t.phases);
        assert_eq!(sum.path_tracing.wall_s, 4.0);
        assert_eq!(sum.cpu_s(), 3.5);
        assert_eq!(sum.named()[2].0, "sync");
    }
}
