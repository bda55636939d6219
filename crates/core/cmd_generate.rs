//! `clevrtex generate`: the variant config with the command line's overrides, the sampler's
//! jobs (`clevrtex-scene`) and the pool run shared with `render` (`run.rs`).

use std::path::PathBuf;
use std::sync::Arc;

use anyhow::{bail, Context};
use clevrtex_dataset::layout;
use clevrtex_dataset::manifest;
use clevrtex_render::pool::{Job, Jobs};
use clevrtex_scene::{Config, Pass, SampleRequest};

use crate::exit::CmdResult;
use crate::run_args::{index_range, parse_passes, within, RunArgs, MAX_ATTEMPTS};

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

/// Layouts drawn by `generate` before any Blender starts, to refuse impossible configs.
const PREFLIGHT_LAYOUTS: usize = 20;

/// One variant's part of a `generate` run: its images `start..start + count` of `total`, the
/// share `shard` of them, with `seed`.
pub(crate) struct Part<'a> {
    /// Built-in variant (when `config` is `None`).
    pub variant: &'a str,
    /// First index.
    pub start: u64,
    /// Images.
    pub count: u64,
    /// Size of the whole variant (fixes the splits); `None`: `start + count`.
    pub total: Option<u64>,
    /// This process's share.
    pub shard: clevrtex_scene::shard::Shard,
    /// Run seed.
    pub seed: u64,
    /// The suite this part belongs to (`--suite`), recorded in its manifest.
    pub suite: Option<&'a str>,
}

/// Run `clevrtex generate` (one variant; `--suite` is `crate::suite::run`, which `main.rs`
/// calls instead, as it runs this file's [`run_part`] per variant).
pub fn run_generate(args: GenerateArgs) -> CmdResult {
    let shard = clevrtex_scene::shard::resolve(args.shard.as_deref(), args.shard_count)?;
    let part = Part {
        variant: &args.variant,
        start: args.start,
        count: args.count.unwrap_or(0),
        total: args.total,
        shard,
        seed: args.seed,
        suite: None,
    };
    run_part(&args, &part, None)
}

/// Make (or with `--estimate`, plan) one variant's `part`; `estimate_sum` adds the
/// prediction's wall and held hours to a suite's.
pub(crate) fn run_part(
    args: &GenerateArgs,
    part: &Part,
    estimate_sum: Option<&std::cell::Cell<(f64, f64)>>,
) -> CmdResult {
    let catalogue = args.run.materials.catalogue()?;
    let mut config = match &args.config {
        Some(path) => {
            let text = std::fs::read_to_string(path).map_err(|e| {
                anyhow::anyhow!(
                    "cannot read config `{}`: {e}\nhint: pass an existing JSON file, e.g. one of `configs/`",
                    path.display()
                )
            })?;
            Config::from_json_str_in(&text, &path.display().to_string(), &catalogue)?
        }
        None => Config::builtin_in(part.variant, &catalogue)?,
    };
    crate::user_materials::apply_material_set(
        &mut config,
        &catalogue,
        args.material_set.as_deref(),
        args.run.materials.materials.is_some() && args.config.is_none(),
    )?;
    if let Some(stream) = &args.layout_stream {
        config
            .set_layout_stream(stream)
            .map_err(anyhow::Error::msg)?;
    }
    let used: std::collections::BTreeSet<String> = config
        .objects
        .materials
        .iter()
        .chain(&config.background.materials)
        .cloned()
        .collect();
    use clevrtex_scene::scene_file::{MAX_IMAGE_SIDE, MAX_SAMPLES};
    if let Some(w) = args.width {
        config.base.render.width = within("--width", w, MAX_IMAGE_SIDE)?;
    }
    if let Some(h) = args.height {
        config.base.render.height = within("--height", h, MAX_IMAGE_SIDE)?;
    }
    if let Some(q) = args.quality {
        q.apply(&mut config.base.render);
    }
    if let Some(s) = args.samples {
        config.base.render.samples = within("--samples", s, MAX_SAMPLES)?;
    }
    if let Some(s) = args.shadow_samples {
        config.base.render.shadow_samples = Some(within("--shadow-samples", s, MAX_SAMPLES)?);
    }
    within("--max-attempts", args.max_attempts, MAX_ATTEMPTS as u32)?;
    // Fail before starting Blender when no layout could ever be drawn, as `sample` does.
    clevrtex_scene::sample::check_feasible(&config)?;
    let passes = match &args.run.passes {
        Some(list) => parse_passes(list)?,
        None => Pass::ALL.to_vec(),
    };
    config.base.passes = passes.clone();
    if part.count == 0 {
        bail!("`-n 0` asks for no images\nhint: pass the number of images, e.g. `-n 100`");
    }
    let end = part
        .start
        .checked_add(part.count)
        .context("`--start` + `-n` overflows\nhint: pass smaller numbers")?;
    crate::run_args::check_index_end(part.start, end)?;
    let total = part.total.unwrap_or(end);
    if total < end {
        bail!("`--total {total}` is smaller than the last index + 1 (`{end}`)\nhint: pass the size of the whole dataset");
    }
    let shard = part.shard;
    let start = part.start;
    // Draw the first layouts before starting Blender: a config whose objects can never be
    // placed fails here once (exit 1), as in `sample`, not once per image into the ledger.
    for index in shard.iter(start, end).take(PREFLIGHT_LAYOUTS) {
        let req = SampleRequest {
            seed: part.seed,
            index,
            attempt: 0,
            total,
        };
        clevrtex_scene::sample(&config, &req)?;
    }
    let config = Arc::new(config);
    let variant = config.name.clone();
    // Job `i` is made when a worker takes it: no list of the run's jobs is held, so
    // `-n 100000000` runs in bounded memory.
    let seed = part.seed;
    let make = {
        let (config, variant, passes) = (Arc::clone(&config), variant.clone(), passes.clone());
        move |i: u64| {
            let index = shard.nth(start, end, i);
            let config = Arc::clone(&config);
            Job {
                index,
                variant: variant.clone(),
                stem: clevrtex_scene::stem(&variant, index),
                passes: passes.clone(),
                scene: Arc::new(move |attempt| {
                    clevrtex_scene::sample(
                        &config,
                        &SampleRequest {
                            seed,
                            index,
                            attempt,
                            total,
                        },
                    )
                    .map_err(|e| e.to_string())
                }),
                resample: true,
                source: None,
            }
        }
    };
    let has_stem = {
        let variant = variant.clone();
        move |stem: &str| {
            layout::parse_stem(stem, "")
                .is_some_and(|(_, v, index)| v == variant && shard.contains(start, end, index))
        }
    };
    let jobs = Jobs::lazy(shard.count(start, end), make, has_stem);
    if args.estimate {
        let r = &config.base.render;
        return crate::estimate::run(crate::estimate::Request {
            run: &args.run,
            jobs: &jobs,
            what: format!(
                "`{variant}` at {}x{}, {} samples{}, passes {}",
                r.width,
                r.height,
                r.samples,
                r.adaptive_threshold
                    .map(|t| format!(" (adaptive threshold {t})"))
                    .unwrap_or_default(),
                passes
                    .iter()
                    .map(|p| p.name())
                    .collect::<Vec<_>>()
                    .join(",")
            ),
            calibrate: args.calibrate,
            tasks: args.tasks,
            max_attempts: args.max_attempts,
            materials: (catalogue, used),
            sum: estimate_sum,
        });
    }
    let ledger = layout::variant_dir(&args.run.out, &variant).join("failures.jsonl");
    let plan = manifest::Plan {
        run: manifest::Manifest {
            variant: variant.clone(),
            seed: part.seed,
            layout_stream: Some(config.layout_stream().to_string()),
            config_hash: manifest::hash_hex(format!("{config:?}").as_bytes()),
            render: serde_json::to_value(&config.base.render).ok(),
            start: part.start,
            end,
            total,
            shard: [shard.k, shard.n],
            tool_version: env!("CARGO_PKG_VERSION").into(),
            tool_commit: crate::provenance::COMMIT.into(),
            tool_modified: crate::provenance::modified(),
            mixed_settings: args.mix_settings,
            suite: part.suite.map(str::to_string),
            command: std::env::args().collect(),
            ..manifest::Manifest::unfinished()
        },
        passes: passes.clone(),
        keep_exr: args.run.keep_exr,
    };
    // Before anything is made: growing a dataset with another `--total` is refused.
    plan.check_splits(&args.run.out, config.splits, args.allow_split_mismatch)?;
    crate::run::run_jobs(
        &args.run,
        jobs,
        ledger,
        args.max_attempts,
        Some(plan),
        (catalogue, used),
    )
}
