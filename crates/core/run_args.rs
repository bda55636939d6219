//! What the commands that render share on their command line: the run options of `generate`
//! and `render` ([`RunArgs`]), `--passes` ([`parse_passes`]), `--device` ([`device_choice`])
//! and the checks of numbers given as flags ([`seconds`], [`positive`], [`within`]); and the
//! dataset folder that `preview` and `report` read and the file they write ([`DatasetDir`]).

use std::path::PathBuf;
use std::time::Duration;

use anyhow::bail;
use clevrtex_render::device::DeviceChoice;
use clevrtex_scene::Pass;

/// Options shared by `generate` and `render`: how to run Blender and write the output.
#[derive(Debug, clap::Args)]
pub struct RunArgs {
    /// Output root; samples go to `OUT/clevrtex_<variant>/<index / 1000>/`.
    #[arg(long, value_name = "OUT")]
    pub(crate) out: PathBuf,
    /// Passes to write, comma-separated: rgb,mask,depth,normal,albedo,shadow (default all
    /// for `generate`; the scene files' own list for `render`).
    #[arg(long, value_delimiter = ',', value_name = "LIST")]
    pub(crate) passes: Option<Vec<String>>,
    /// Blender: an executable, or a Python that imports `bpy` (default: `blender` on PATH, else
    /// `./.venv-bpy/bin/python`).
    #[arg(long, env = "CLEVRTEX_BLENDER", value_name = "PATH")]
    pub(crate) blender: Option<PathBuf>,
    /// Blender processes rendering in parallel (default: 2 on machines with 2+ cores).
    #[arg(long, value_name = "N")]
    pub(crate) workers: Option<usize>,
    /// Cycles device: `auto` (the best GPU kind Blender reports: OptiX, CUDA, HIP; else the
    /// CPU), `cpu`, `cuda`, `optix` or `hip`. With N GPUs, one worker per GPU (pinned by its
    /// index) and `--workers` defaults to N.
    #[arg(long, default_value = "auto", value_name = "DEVICE")]
    pub(crate) device: String,
    /// Cycles threads per Blender process (default: cores / workers).
    #[arg(long, value_name = "T")]
    pub(crate) threads: Option<u32>,
    /// Time limit per render request, seconds; a worker over it is killed and the scene
    /// retried. Default: 600 + 8 per sample at 320x240 (doubled with the shadow pass), and
    /// a worker silent for 300 s counts as hung.
    #[arg(long, value_name = "SECONDS")]
    pub(crate) timeout: Option<f64>,
    /// Time limit for a Blender worker to start (load the bridge and answer `ready`), seconds.
    #[arg(long, default_value_t = clevrtex_render::STARTUP_TIMEOUT.as_secs_f64(), value_name = "SECONDS")]
    pub(crate) startup_timeout: f64,
    /// Restarts of a crashed or hung worker per scene before it goes to the failure ledger.
    #[arg(long, default_value_t = 2, value_name = "N")]
    pub(crate) retries: u32,
    /// Also keep the float EXRs (`<stem>_passes.exr`, and with the shadow pass
    /// `<stem>_shadow.exr`).
    #[arg(long)]
    pub(crate) keep_exr: bool,
    /// Redo samples that are already complete (default: skip them, i.e. resume).
    #[arg(long)]
    pub(crate) overwrite: bool,
    /// Stop at the first failed scene instead of recording it in the ledger and going on.
    #[arg(long)]
    pub(crate) fail_fast: bool,
    #[command(flatten)]
    pub(crate) materials: crate::user_materials::MaterialsArg,
}

/// `v`, which must not be 0 (given as `flag`).
pub(crate) fn positive(flag: &str, v: u32) -> anyhow::Result<u32> {
    if v == 0 {
        bail!("`{flag} 0` is not allowed\nhint: pass a positive number");
    }
    Ok(v)
}

/// A positive, finite number of seconds given as `flag`.
pub(crate) fn seconds(flag: &str, v: f64) -> anyhow::Result<Duration> {
    if !(v > 0.0 && v.is_finite()) {
        bail!("`{flag} {v}` must be a positive number of seconds\nhint: e.g. `{flag} 120`");
    }
    Ok(Duration::from_secs_f64(v))
}

/// `v`, which must be 1 to `max` (given as `flag`).
pub(crate) fn within(flag: &str, v: u32, max: u32) -> anyhow::Result<u32> {
    if v > max {
        bail!("`{flag} {v}` is more than the {max} allowed\nhint: pass 1 to {max}");
    }
    positive(flag, v)
}

/// `--passes`: the passes named, each once, in the pass table's order.
pub(crate) fn parse_passes(list: &[String]) -> anyhow::Result<Vec<Pass>> {
    let mut out = Vec::new();
    for name in list.iter().map(|s| s.trim()).filter(|s| !s.is_empty()) {
        match Pass::from_name(name) {
            Some(p) if !out.contains(&p) => out.push(p),
            Some(_) => {}
            None => bail!(
                "unknown pass `{name}`\nhint: use a comma-separated list of {}",
                Pass::ALL.map(Pass::name).join(", ")
            ),
        }
    }
    if out.is_empty() {
        bail!(
            "`--passes` is empty\nhint: name at least one of {}",
            Pass::ALL.map(Pass::name).join(", ")
        );
    }
    out.sort();
    Ok(out)
}

/// `--device`: `auto`, `cpu`, or a GPU kind.
pub(crate) fn device_choice(name: &str) -> anyhow::Result<DeviceChoice> {
    let Some(choice) = DeviceChoice::parse(name) else {
        bail!(
            "unknown device `{name}`\nhint: use one of {}",
            DeviceChoice::ALL.map(|(_, n)| n).join(", ")
        );
    };
    Ok(choice)
}

/// What `preview` and `report` read and write.
#[derive(Debug, clap::Args)]
pub struct DatasetDir {
    /// The dataset: an output folder of `clevrtex generate`, a `clevrtex_<variant>` folder, or
    /// the downloaded ClevrTex.
    #[arg(value_name = "DIR")]
    pub(crate) dir: PathBuf,
    /// The file to write: the sheet (PNG) for `preview`, the page (HTML) for `report`.
    #[arg(long, value_name = "FILE")]
    pub(crate) out: PathBuf,
}
