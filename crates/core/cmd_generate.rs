//! `clevrtex generate`: the variant config read, its part prepared by the render crate
//! (`clevrtex_render::generate::prepare`: overrides, checks, jobs, manifest) and run by the
//! pool run shared with `render` (`run.rs`), or planned (`estimate.rs`).

use std::path::PathBuf;

use clevrtex_dataset::manifest;
use clevrtex_render::generate;
use clevrtex_scene::config::Overrides;
use clevrtex_scene::Config;

use crate::exit::CmdResult;
use crate::run_args::{index_range, read_config, RunArgs};

/// Arguments of `clevrtex generate`.
#[derive(Debug, clap::Args)]
#[command(after_help = clevrtex_scene::shard::SHARD_HELP)]
pub struct GenerateArgs {
    #[arg(long, default_value = "full", conflicts_with_all = ["config", "suite"],
        help = format!("Built-in variant: {}", Config::variant_list()))]
    variant: String,
    /// A variant config file (JSON, like those in `configs/`) instead of `--variant`.
    #[arg(long, value_name = "FILE")]
    config: Option<PathBuf>,
    /// Number of images, 1 to 100000000 (with `--start`, indices stay below 100000000).
    #[arg(short = 'n', long = "count", value_name = "N", value_parser = index_range(),
        required_unless_present = "suite")]
    count: Option<u64>,
    /// Make a whole benchmark suite into `--out`: `clevrtex` is the published ClevrTex (full
    /// 50,000 images; pbg, vbg, grassbg, camo 20,000 each; outd 10,000, test only), each
    /// variant at its fixed total with its own layout stream; `--shard` splits the whole
    /// suite. Recorded in `OUT/SUITE.json`; `clevrtex verify OUT` checks the suite.
    #[arg(long, value_name = "NAME",
        conflicts_with_all = ["config", "count", "start", "total", "layout_stream", "allow_split_mismatch"])]
    pub(crate) suite: Option<String>,
    /// With `--suite`: make every variant this fraction of its published size (rounded), e.g.
    /// `--scale 0.001` for a try; a scale that empties a variant is refused.
    #[arg(long, value_name = "F", requires = "suite")]
    pub(crate) scale: Option<f64>,
    /// Run seed: with the image index it fixes every random draw.
    #[arg(long, default_value_t = 0)]
    pub(crate) seed: u64,
    /// Draw layouts from this variant's stream instead of this variant's own (the default:
    /// the same `--seed` gives unrelated layouts in every variant). `--layout-stream full`
    /// gives e.g. `camo` the layouts of `full` (same seed): the controlled comparison of
    /// materials on one set of layouts; `shared` is the one stream every variant drew from up
    /// to clevrtex 0.1. Recorded in scene files, metadata and manifests (`layout_stream`).
    #[arg(long, value_name = "VARIANT")]
    layout_stream: Option<String>,
    /// First image index; images `START..START+N` are made.
    #[arg(long, default_value_t = 0, value_name = "I", value_parser = index_range())]
    start: u64,
    /// Size of the whole dataset, which fixes the splits (first 10% test, next 10% val, rest
    /// train), at most 100000000 [default: START + N].
    #[arg(long, value_name = "T", value_parser = index_range())]
    total: Option<u64>,
    /// Render into a folder whose runs have another `--total` although the dataset's recorded
    /// splits then differ from the public loader's (refused by default: every run of a
    /// dataset should pass the same `--total`).
    #[arg(long)]
    allow_split_mismatch: bool,
    /// Make only the images with `index % N == K` (0 <= K < N), as `clevrtex sample` does:
    /// N shards together make every image exactly once.
    #[arg(long, value_name = "K/N")]
    pub(crate) shard: Option<String>,
    /// Number of shards when the shard index comes from JOB_COMPLETION_INDEX.
    #[arg(long, value_name = "N", env = "CLEVRTEX_SHARD_COUNT")]
    pub(crate) shard_count: Option<u64>,
    /// Image width in pixels, 1 to 4096 (default 320).
    #[arg(long)]
    width: Option<u32>,
    /// Image height in pixels, 1 to 4096 (default 240).
    #[arg(long)]
    height: Option<u32>,
    /// Cycles samples per pixel, 1 to 65536 (default from the config).
    #[arg(long)]
    samples: Option<u32>,
    /// Samples of the shadow pass's render (default: three eighths of the samples, at most
    /// 64; RMSE ~0.018 at 8, ~0.010 at 16, ~0.008 at 24; docs/performance.md, "Shadow pass"),
    /// 1 to 65536.
    #[arg(long, value_name = "N")]
    shadow_samples: Option<u32>,
    /// Quality preset: draft, fast, standard, high or reference (samples, adaptive threshold,
    /// bounces, denoising; see docs/performance.md). `fast` denoises the RGB with
    /// OpenImageDenoise and needs a Blender 4.x (e.g. `--blender .venv-bpy/bin/python`).
    /// `--samples` still overrides the sample count.
    #[arg(long, value_name = "PRESET")]
    quality: Option<clevrtex_scene::quality::Quality>,
    /// Draw the variant's textured materials (every material list of objects or backdrop
    /// made only of `main`/`ood` materials) from this set instead: `user` (the materials of
    /// `--materials DIR`), `main` or `ood`. Default with `--materials` and a built-in
    /// `--variant`: `user` (the public generator's "replace `data/materials`"); with
    /// `--config`, the config names its materials. Layouts stay the same: the controlled
    /// comparison of a user library against the built-in catalogue.
    #[arg(long, value_name = "SET")]
    material_set: Option<String>,
    /// Layout attempts per image when objects are hidden, before the image fails (1 to 1000).
    #[arg(long, default_value_t = 20, value_name = "N")]
    max_attempts: u32,
    /// Plan instead of make: render a few calibration images of these settings (visibility
    /// pass and rejects included) in a scratch folder, nothing into `--out`, and print the
    /// predicted wall time, CPU core-hours or GPU hours and images/hour for `-n` with these
    /// workers x threads (docs/performance.md, "Planning a run").
    #[arg(long)]
    pub(crate) estimate: bool,
    /// With `--estimate`: calibration images, 2 to 100 [default: 2 per worker, at least 4].
    #[arg(long, value_name = "K", requires = "estimate")]
    calibrate: Option<u32>,
    /// With `--estimate`: also predict an array of this many tasks (SLURM `--array`, a
    /// Kubernetes Job's `completions`), each on a machine like this one; 1 to `-n`.
    #[arg(long, value_name = "TASKS", requires = "estimate")]
    tasks: Option<u64>,
    /// Write this run into a folder of runs with other settings (image size, samples, seed,
    /// config, materials) on purpose: recorded in its manifest, so `verify` names the mix
    /// without failing the dataset (docs/runs.md, "One dataset, one set of settings").
    #[arg(long)]
    mix_settings: bool,
    #[command(flatten)]
    pub(crate) run: RunArgs,
}

/// One variant's part of a `generate` run: the render crate's part, the variant and suite.
pub(crate) struct Part<'a> {
    /// Built-in variant (when `config` is `None`).
    pub variant: &'a str,
    /// The images, the shard, the seed.
    pub images: generate::Part,
    /// The suite this part belongs to (`--suite`), recorded in its manifest.
    pub suite: Option<&'a str>,
}

/// Run `clevrtex generate` (one variant; `--suite` is `crate::suite::run`, which `main.rs`
/// calls instead, as it runs this file's [`run_part`] per variant).
pub fn run_generate(args: GenerateArgs) -> CmdResult {
    // `--scale` sizes a suite: without `--suite` it would be ignored (a 320x240 run of the
    // default count instead of the try asked for).
    if let Some(scale) = args.scale {
        anyhow::bail!("`--scale {scale}` sizes a benchmark suite, and no `--suite` is given: it would be ignored\nhint: pass `--suite clevrtex --scale {scale}`, or leave `--scale` out");
    }
    let shard = clevrtex_scene::shard::resolve(args.shard.as_deref(), args.shard_count)?;
    // A suite's folder is made by `--suite` only: a plain run would rewrite a suite variant's
    // manifest without its suite, or add a variant outside the suite's plan.
    if !args.estimate {
        clevrtex_dataset::suite::refuse_plain_run(&args.run.out, &args.variant)?;
    }
    let images = generate::Part {
        start: args.start,
        count: args.count.unwrap_or(0),
        total: args.total,
        shard,
        seed: args.seed,
    };
    let part = Part {
        variant: &args.variant,
        images,
        suite: None,
    };
    run_part(&args, &part, None, None)
}

/// Make (or with `--estimate`, plan) one variant's `part`; `estimate_sum` adds the
/// prediction's wall and held hours to a suite's; `keep` holds the workers a suite's variants
/// share (`clevrtex_render::kept`).
pub(crate) fn run_part(
    args: &GenerateArgs,
    part: &Part,
    estimate_sum: Option<&std::cell::Cell<(f64, f64)>>,
    keep: Option<&std::sync::Arc<clevrtex_render::kept::KeptWorkers>>,
) -> CmdResult {
    let catalogue = args.run.materials.catalogue()?;
    let hint = "pass an existing JSON file, e.g. one of `configs/`";
    let config = read_config(args.config.as_deref(), part.variant, &catalogue, hint)?;
    let prepared = generate::prepare(generate::Request {
        config,
        catalogue: &catalogue,
        material_set: (
            args.material_set.as_deref(),
            args.run.materials.materials.is_some() && args.config.is_none(),
        ),
        overrides: &Overrides {
            layout_stream: args.layout_stream.clone(),
            width: args.width,
            height: args.height,
            quality: args.quality,
            samples: args.samples,
            shadow_samples: args.shadow_samples,
        },
        max_attempts: args.max_attempts,
        passes: args.run.passes.as_deref(),
        part: part.images,
        out: &args.run.out,
        keep_exr: args.run.keep_exr,
        manifest: manifest::Manifest {
            tool_version: env!("CARGO_PKG_VERSION").into(),
            tool_commit: crate::provenance::COMMIT.into(),
            tool_modified: crate::provenance::modified(),
            mixed_settings: args.mix_settings,
            suite: part.suite.map(str::to_string),
            command: std::env::args().collect(),
            ..manifest::Manifest::unfinished()
        },
    })
    .map_err(anyhow::Error::msg)?;
    if args.estimate {
        return crate::estimate::run(crate::estimate::Request {
            run: &args.run,
            jobs: &prepared.jobs.jobs,
            what: prepared.what,
            calibrate: args.calibrate,
            tasks: args.tasks,
            max_attempts: args.max_attempts,
            materials: (catalogue, prepared.jobs.used),
            sum: estimate_sum,
        });
    }
    // Before anything is made: growing a dataset with another `--total` is refused.
    let (plan, a) = (prepared.plan, args);
    plan.check_splits(&a.run.out, prepared.splits, a.allow_split_mismatch)?;
    crate::run::run_jobs(
        &a.run,
        prepared.jobs,
        a.max_attempts,
        (Some(plan), keep),
        catalogue,
    )
}
