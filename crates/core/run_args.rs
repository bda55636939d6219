//! What the commands that render share on their command line: the run options of `generate`
//! and `render` ([`RunArgs`]), `--device` ([`device_choice`]) and `--timeout`'s check
//! ([`seconds`]; the other numbers' are `clevrtex_scene::config::within`); and the
//! dataset folder that `preview` and `report` read and the file they write ([`DatasetDir`]).

use std::path::PathBuf;
use std::time::Duration;

use anyhow::bail;
use clevrtex_render::device::DeviceChoice;

/// Options shared by `generate` and `render`: how to run Blender and write the output.
#[derive(Debug, Clone, clap::Args)]
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
    /// Blender processes rendering in parallel, 1 to 1024. Default on GPUs: one per 4 cores per
    /// GPU, 1 to 4 per GPU (a worker's scene build and visibility pass leave its GPU idle);
    /// on the CPU 1 with one core, 2 with 2-15 cores (one worker's scene build, visibility pass
    /// and writing overlap the other's render), cores / 8 from 16 cores (docs/performance.md,
    /// "Workers x threads").
    #[arg(long, value_name = "N")]
    pub(crate) workers: Option<usize>,
    /// Cycles device: `auto` (the best GPU kind Blender reports: OptiX, CUDA, HIP; else the
    /// CPU), `cpu`, `cuda`, `optix` or `hip`. With N GPUs, the workers are spread evenly over
    /// them (each pinned to one GPU by its index); see `--workers` for how many.
    #[arg(long, default_value = "auto", value_name = "DEVICE")]
    pub(crate) device: String,
    /// Cycles threads per Blender process, 1 to 1024 (default: cores / workers).
    #[arg(long, value_name = "T", value_parser = threads_range::<u32>())]
    pub(crate) threads: Option<u32>,
    /// Time limit per render request, seconds; a worker over it is killed and the scene
    /// retried. Default: 600 + 8 per sample at 320x240 (doubled with the shadow pass), and
    /// a worker silent for 300 s counts as hung. More than 0, at most 604800 (a week).
    #[arg(long, value_name = "SECONDS")]
    pub(crate) timeout: Option<f64>,
    /// Time limit for a Blender worker to start (load the bridge and answer `ready`), seconds:
    /// more than 0, at most 604800.
    #[arg(long, default_value_t = clevrtex_render::STARTUP_TIMEOUT.as_secs_f64(), value_name = "SECONDS")]
    pub(crate) startup_timeout: f64,
    /// Restarts of a crashed or hung worker per scene before it goes to the failure ledger,
    /// 0 to 100.
    #[arg(long, default_value_t = 2, value_name = "N", value_parser = clap::value_parser!(u32).range(0..=MAX_RETRIES as i64))]
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
    /// Recycle a Blender worker (it quits after its image; a fresh one makes the next) when
    /// its resident memory passes this many GiB, more than 0 [default: half the machine's
    /// memory shared by the workers, at least 2]. Never during an image.
    #[arg(long, value_name = "GIB")]
    pub(crate) max_worker_memory: Option<f64>,
    /// Recycle each Blender worker after this many images, 1 to 100000000 [default: never].
    #[arg(long, value_name = "N", value_parser = clap::value_parser!(u64).range(1..=100_000_000))]
    pub(crate) recycle_after: Option<u64>,
    #[command(flatten)]
    pub(crate) materials: crate::user_materials::MaterialsArg,
}

// ---- ranges of numeric flags ---------------------------------------------------------
//
// Every numeric flag has a range, refused by clap before anything runs (exit 2, naming the
// flag and the range); README.md, "Ranges of numeric flags", lists them.

/// Most threads, workers or jobs any flag may ask for: far above any machine's cores, far
/// below what exhausts a process's threads.
pub(crate) const MAX_THREADS: u64 = 1024;
/// Longest time limit any flag may give, seconds: one week.
pub(crate) const MAX_SECONDS: f64 = 7.0 * 24.0 * 3600.0;
/// Most restarts of a worker per scene.
pub(crate) const MAX_RETRIES: u64 = 100;
/// `--jobs`, `--workers`, `--threads`: 1 to [`MAX_THREADS`].
pub(crate) fn threads_range<T>() -> clap::builder::RangedU64ValueParser<T>
where
    T: TryFrom<u64> + Clone + Send + Sync + 'static,
    <T as TryFrom<u64>>::Error: Send + Sync + 'static + std::error::Error + ToString,
{
    clap::builder::RangedU64ValueParser::<T>::new().range(1..=MAX_THREADS)
}

/// `-n`, `--start`, `--total`: 0 to the dataset cap (`MAX_RUN_INDICES`, 100000000 images);
/// the sum `--start + -n` is checked by the command.
pub(crate) fn index_range() -> clap::builder::RangedU64ValueParser<u64> {
    clap::builder::RangedU64ValueParser::<u64>::new().range(0..=clevrtex_scene::bounds::INDEX_END)
}

/// A number of seconds given as `flag`: more than 0 and at most [`MAX_SECONDS`] (a week;
/// `1e300` overflowed a duration and panicked).
pub(crate) fn seconds(flag: &str, v: f64) -> anyhow::Result<Duration> {
    if !(v > 0.0 && v <= MAX_SECONDS) {
        // 1e300 as written, not as 301 digits.
        let shown = if v.is_finite() && v.abs() < 1e9 {
            v.to_string()
        } else {
            format!("{v:e}")
        };
        bail!("`{flag} {shown}` must be a positive number of seconds, at most {MAX_SECONDS} (one week)\nhint: e.g. `{flag} 120`");
    }
    Ok(Duration::from_secs_f64(v))
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

/// The config of `sample` and `generate`: the file `--config` (read, then checked against
/// `cat`; `hint` ends the message when it cannot be read), else the built-in `variant`.
pub(crate) fn read_config(
    config: Option<&std::path::Path>,
    variant: &str,
    cat: &clevrtex_materials::Catalogue,
    hint: &str,
) -> anyhow::Result<clevrtex_scene::Config> {
    let Some(path) = config else {
        return Ok(clevrtex_scene::Config::builtin_in(variant, cat)?);
    };
    // The cause goes before the hint, which is the message's last line.
    let text = std::fs::read_to_string(path).map_err(|e| {
        anyhow::anyhow!("cannot read config `{}`: {e}\nhint: {hint}", path.display())
    })?;
    let name = path.display().to_string();
    Ok(clevrtex_scene::Config::from_json_str_in(&text, &name, cat)?)
}
