//! `clevrtex materials`: list the catalogue, print the resolved recipes, render a contact
//! sheet, check that every material builds, and measure distinctness and cost.
//!
//! The renders are `material` requests of the bridge protocol (`docs/bridge-protocol.md`),
//! one per material, sent to one Blender worker with `generate`'s failure policy: a time
//! limit per request, a crashed or hung worker restarted and the request retried
//! (`--retries`), Ctrl-C stopping Blender at once.

use std::io::Write;
use std::path::PathBuf;

use anyhow::bail;
use clevrtex_materials::Catalogue;

use clevrtex_report::materials::{self, batches, cost, figures, measure_output, sheet, text};

use clevrtex_render::material_renders::RenderOptions;

use crate::exit::{command_error, command_error_any, CmdResult, OK};
use crate::interrupt::{self, OnInterrupt};

/// Arguments of `clevrtex materials`.
#[derive(Debug, clap::Args)]
pub struct Args {
    #[command(subcommand)]
    command: Sub,
    /// Extra materials: `.json` files in our format and `.blend` files with a ClevrTex-style
    /// node group (inputs Color/Random/Displacement/Scale, outputs Shader and Displacement),
    /// and folders of Poly Haven or ambientCG texture maps (docs/materials.md).
    #[arg(long, global = true, value_name = "DIR")]
    materials: Option<PathBuf>,
}

#[derive(Debug, clap::Subcommand)]
enum Sub {
    /// List every material: name, set, whether it displaces, description.
    List,
    /// Print the resolved catalogue (`materials.json`, as the Blender bridge receives it).
    Json,
    /// Render a labelled contact sheet: each material on a sphere and a cube.
    Sheet(SheetArgs),
    /// Build and render every material small; fail on Blender errors or pink pixels.
    Check(BatchArgs),
    /// Distinctness: texture statistics of flat-lit tiles, nearest neighbours, near-copies.
    Stats(StatsArgs),
    /// Render time of each material on a sphere, relative to `plain`.
    Cost(CostArgs),
    /// Whether every Blender found renders each material alike: mean luminance and depth of
    /// the material's pixels as the displaced backdrop and on the objects of one scene, per
    /// Blender against the first; fails past 3% in luminance or 1% in depth.
    Parity(ParityArgs),
    /// Measure a rendered dataset (no Blender): albedo spread, interior/boundary gradient
    /// ratio and scale ratio, per variant and per material (docs/materials.md).
    Measure(MeasureArgs),
}

#[derive(Debug, clap::Args)]
struct MeasureArgs {
    /// The dataset: the `--out` folder of `clevrtex generate` or one `clevrtex_<variant>`
    /// folder (needs the mask; the RGB image for the gradient ratio, the albedo pass for the
    /// spread and the scale ratio).
    dataset: PathBuf,
    /// Print JSON (every image's figures and the summaries) instead of tables.
    #[arg(long)]
    json: bool,
}

#[derive(Debug, clap::Args)]
struct ParityArgs {
    /// Which materials: main, ood, basic, background, user or all.
    #[arg(long, default_value = "all")]
    set: String,
    /// Only these materials (comma-separated), instead of `--set`.
    #[arg(long, value_delimiter = ',')]
    names: Vec<String>,
    /// A Blender to compare (repeatable; the first is the reference). Default: every Blender
    /// `clevrtex doctor` finds (`CLEVRTEX_BLENDER`, `blender` on `PATH`, `./.venv-bpy`).
    #[arg(long = "blender", value_name = "PATH")]
    blenders: Vec<PathBuf>,
    /// Only this role: `backdrop` (displaced, no objects) or `object` (default: both).
    #[arg(long = "as", value_name = "ROLE", value_parser = ["backdrop", "object"])]
    role: Option<String>,
    /// Image width in pixels, 16 to 4096 (height is 3/4 of it).
    #[arg(long, default_value_t = 96, value_parser = clap::value_parser!(u32).range(16..=4096))]
    size: u32,
    /// Samples per pixel, 1 to 65536.
    #[arg(long, default_value_t = 16, value_parser = clap::value_parser!(u32).range(1..=65536))]
    samples: u32,
    #[command(flatten)]
    limits: Limits,
}

#[derive(Debug, clap::Args)]
struct StatsArgs {
    #[command(flatten)]
    batch: BatchArgs,
    /// Tile size in pixels (16 to 4096).
    #[arg(long, default_value_t = 128, value_parser = clap::value_parser!(u32).range(16..=4096))]
    size: u32,
    /// Samples per pixel, 1 to 65536.
    #[arg(long, default_value_t = 16, value_parser = clap::value_parser!(u32).range(1..=65536))]
    samples: u32,
    /// Keep the tiles here (default: a temporary directory).
    #[arg(long)]
    out_dir: Option<PathBuf>,
}

#[derive(Debug, clap::Args)]
struct CostArgs {
    #[command(flatten)]
    batch: BatchArgs,
    /// Image size in pixels (16 to 4096).
    #[arg(long, default_value_t = 160, value_parser = clap::value_parser!(u32).range(16..=4096))]
    size: u32,
    /// Samples per pixel, 1 to 65536.
    #[arg(long, default_value_t = 64, value_parser = clap::value_parser!(u32).range(1..=65536))]
    samples: u32,
}

#[derive(Debug, clap::Args)]
struct BatchArgs {
    /// Which materials: main, ood, basic, background, user or all.
    #[arg(long, default_value = "all")]
    set: String,
    /// Only these materials (comma-separated), instead of `--set`.
    #[arg(long, value_delimiter = ',')]
    names: Vec<String>,
    /// Blender executable (default: `CLEVRTEX_BLENDER`, else `blender` on `PATH`).
    #[arg(long, env = "CLEVRTEX_BLENDER")]
    blender: Option<PathBuf>,
    #[command(flatten)]
    limits: Limits,
}

/// The limits of a batch's Blender worker.
#[derive(Debug, clap::Args)]
struct Limits {
    /// Cycles threads, 0 to 1024 (0: automatic).
    #[arg(long, default_value_t = 0, value_parser = clap::value_parser!(u32).range(0..=crate::run_args::MAX_THREADS as i64))]
    threads: u32,
    /// Time limit per material render, seconds; a worker over it is killed and the render
    /// retried. Default: 600 + 8 per sample at 320x240, and a worker silent for 300 s counts
    /// as hung. More than 0, at most 604800 (a week).
    #[arg(long, value_name = "SECONDS")]
    timeout: Option<f64>,
    /// Restarts of a crashed or hung Blender worker per material before the command stops
    /// (0 to 100).
    #[arg(long, default_value_t = 2, value_name = "N", value_parser = clap::value_parser!(u32).range(0..=crate::run_args::MAX_RETRIES as i64))]
    retries: u32,
    /// Time limit for a Blender worker to start (load the bridge and answer `ready`), seconds:
    /// more than 0, at most 604800.
    #[arg(long, default_value_t = clevrtex_render::STARTUP_TIMEOUT.as_secs_f64(), value_name = "SECONDS")]
    startup_timeout: f64,
}

impl BatchArgs {
    /// What the material renders take of these arguments, checked; the Blender found and a
    /// Ctrl-C handler that stops it installed.
    fn render_options(&self) -> anyhow::Result<RenderOptions> {
        let blender = clevrtex_render::blender::locate(self.blender.as_deref())?;
        self.limits.render_options(blender)
    }
}

impl Limits {
    /// The render options of `blender` with these limits, checked; a Ctrl-C handler that
    /// stops Blender installed.
    fn render_options(&self, blender: PathBuf) -> anyhow::Result<RenderOptions> {
        let timeout = match self.timeout {
            Some(t) => Some(crate::run_args::seconds("--timeout", t)?),
            None => None,
        };
        let interrupt = interrupt::flag(OnInterrupt::Stop {
            message: "stopping Blender",
        });
        let startup_timeout = crate::run_args::seconds("--startup-timeout", self.startup_timeout)?;
        Ok(RenderOptions {
            blender,
            threads: self.threads,
            timeout,
            retries: self.retries,
            startup_timeout,
            interrupt,
        })
    }
}

#[derive(Debug, clap::Args)]
struct SheetArgs {
    #[command(flatten)]
    batch: BatchArgs,
    /// Output PNG.
    #[arg(long)]
    out: PathBuf,
    /// Cell width in pixels, 16 to 4096 (height is 3/4 of it).
    #[arg(long, default_value_t = 240, value_parser = clap::value_parser!(u32).range(16..=4096))]
    size: u32,
    /// Samples per pixel, 1 to 65536.
    #[arg(long, default_value_t = 24, value_parser = clap::value_parser!(u32).range(1..=65536))]
    samples: u32,
    /// Cells per row, 1 to 256.
    #[arg(long, default_value_t = 8, value_parser = clap::builder::RangedU64ValueParser::<usize>::new().range(1..=256))]
    cols: usize,
    /// Cell cache (default: `$XDG_CACHE_HOME/clevrtex/sheet` or `~/.cache/clevrtex/sheet`).
    /// Cells are keyed by the material's content hash, the bridge scripts and the settings.
    #[arg(long)]
    cache: Option<PathBuf>,
}

/// Run `clevrtex materials`.
pub fn run(args: Args) -> CmdResult {
    let cat = crate::user_materials::load(args.materials.as_deref())?;
    match args.command {
        Sub::List => {
            let mut out = std::io::stdout().lock();
            for line in text::list_lines(&cat) {
                if writeln!(out, "{line}").is_err() {
                    break;
                }
            }
            Ok(OK)
        }
        Sub::Json => {
            let _ = writeln!(std::io::stdout().lock(), "{}", cat.resolved_json());
            Ok(OK)
        }
        Sub::Sheet(a) => {
            // Not into the user materials read, nor into the cell cache.
            let cache = sheet::cache_dir(a.cache.clone());
            let mut read = vec![cache.as_path()];
            read.extend(args.materials.as_deref());
            clevrtex_dataset::out_path::check(&a.out, "--out", &read)
                .map_err(anyhow::Error::msg)?;
            sheet(&cat, a)
        }
        Sub::Check(a) => check(&cat, a),
        Sub::Stats(a) => stats(&cat, a),
        Sub::Cost(a) => cost(&cat, a),
        Sub::Parity(a) => parity(&cat, a),
        Sub::Measure(a) => measure(a),
    }
}

fn sheet(cat: &Catalogue, a: SheetArgs) -> CmdResult {
    let names = materials::select(cat, &a.batch.set, &a.batch.names)?;
    if names.is_empty() {
        bail!(
            "no materials in set `{}`\nhint: pick another `--set`",
            a.batch.set
        );
    }
    let cache = sheet::cache_dir(a.cache.clone());
    sheet::make(
        cat,
        &names,
        &|| a.batch.render_options(),
        (a.size, a.samples, a.cols),
        &cache,
        &a.out,
        &mut |line| eprintln!("{line}"),
    )
    .map_err(command_error_any)?;
    Ok(OK)
}

fn check(cat: &Catalogue, a: BatchArgs) -> CmdResult {
    let names = materials::select(cat, &a.set, &a.names)?;
    let dir = std::env::temp_dir().join(format!("clevrtex-check-{}", std::process::id()));
    let outcomes =
        batches::check(cat, &names, &a.render_options()?, &dir).map_err(command_error)?;
    let (lines, failed) = text::check_text(&names, &outcomes);
    out(&lines);
    if failed > 0 {
        bail!(
            "{failed} of {} material(s) failed to build or render\nhint: the traceback above names the block and parameter",
            outcomes.len()
        );
    }
    Ok(OK)
}

fn stats(cat: &Catalogue, a: StatsArgs) -> CmdResult {
    let (names, d) = batches::distinctness(
        cat,
        (&a.batch.set, &a.batch.names),
        &|| a.batch.render_options(),
        (a.size, a.samples),
        a.out_dir.as_deref(),
    )
    .map_err(command_error_any)?;
    let (table, near) = text::stats_text(&names, &d);
    out(&table);
    if !near.is_empty() {
        bail!(
            "{} pair(s) of materials are closer than the median self-distance {:.3}:\n{}\nhint: change the colours or the pattern scale of one of each pair",
            near.len(),
            d.threshold,
            near.join("\n")
        );
    }
    Ok(OK)
}

fn cost(cat: &Catalogue, a: CostArgs) -> CmdResult {
    let opts = || a.batch.render_options();
    let (names, times) = batches::costs(
        cat,
        (&a.batch.set, &a.batch.names),
        &opts,
        (a.size, a.samples),
    )
    .map_err(command_error_any)?;
    let c = cost::relative(&names, &times);
    out(&text::cost_text(&names, &times, &c));
    Ok(OK)
}

fn parity(cat: &Catalogue, a: ParityArgs) -> CmdResult {
    use clevrtex_report::materials::parity::{self, Role};
    let names = materials::select(cat, &a.set, &a.names)?;
    if names.is_empty() {
        bail!(
            "no materials in set `{}`\nhint: pick another `--set`",
            a.set
        );
    }
    let roles = match a.role.as_deref() {
        Some("backdrop") => vec![Role::Backdrop],
        Some(_) => vec![Role::Object],
        None => vec![Role::Backdrop, Role::Object],
    };
    let blenders: Vec<PathBuf> = if a.blenders.is_empty() {
        clevrtex_render::blender::candidates()
            .into_iter()
            .map(|(p, _)| p)
            .collect()
    } else {
        a.blenders
            .iter()
            .map(|b| clevrtex_render::blender::locate(Some(b)))
            .collect::<Result<_, _>>()?
    };
    if blenders.len() < 2 {
        bail!(
            "`materials parity` compares two or more Blenders, but has {}\nhint: install a second one (`./scripts/setup.sh --bpy 4.5` makes `./.venv-bpy`), or pass each with `--blender`; `clevrtex doctor` lists those found",
            blenders
                .first()
                .map_or("none".to_string(), |b| format!("only `{}`", b.display()))
        );
    }
    let opts = a.limits.render_options(blenders[0].clone())?;
    let settings = parity::Settings {
        width: a.size,
        samples: a.samples,
    };
    let columns = parity::run(
        cat,
        &names,
        &roles,
        &blenders,
        &opts,
        settings,
        &mut |line| eprintln!("{line}"),
    )?;
    let (table, past) = parity::table(&columns);
    out(&format!(
        "{}\n{table}",
        parity::header(names.len(), &roles, settings, &columns)
    ));
    let rows = names.len() * roles.len();
    if past > 0 {
        bail!(
            "{past} of {rows} (material, role) pair(s) render past the bounds on some Blender (luminance {:.0}%, depth {:.0}%; marked **past** above)\nhint: docs/notes/materials.md (issue 50) says which differences are known and why; raise `--samples` to tell noise from a difference",
            100.0 * parity::LUMINANCE_BOUND,
            100.0 * parity::DEPTH_BOUND
        );
    }
    eprintln!(
        "all {rows} (material, role) pair(s) within the bounds (luminance {:.0}%, depth {:.0}%)",
        100.0 * parity::LUMINANCE_BOUND,
        100.0 * parity::DEPTH_BOUND
    );
    Ok(OK)
}

fn measure(a: MeasureArgs) -> CmdResult {
    let samples = figures::measure_dataset(&a.dataset)?;
    let mut out = std::io::stdout().lock();
    if a.json {
        let _ = writeln!(out, "{:#}", measure_output::json(&samples));
    } else {
        let _ = write!(out, "{}", measure_output::tables(&samples));
    }
    Ok(OK)
}

/// `text` on stdout; a closed stdout (`| head`) is not an error.
fn out(text: &str) {
    let _ = std::io::stdout().lock().write_all(text.as_bytes());
}
