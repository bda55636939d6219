//! `clevrtex generate`: the variant config with the command line's overrides, the sampler's
//! jobs (`clevrtex-scene`) and the pool run shared with `render` (`run.rs`).

use std::path::PathBuf;
use std::sync::Arc;

use anyhow::{bail, Context};
use clevrtex_render::manifest;
use clevrtex_render::pool::Job;
use clevrtex_scene::{layout, Config, Pass, SampleRequest};

use crate::exit::CmdResult;
use crate::run_args::{parse_passes, positive, within, RunArgs};

/// Arguments of `clevrtex generate`.
#[derive(Debug, clap::Args)]
#[command(after_help = clevrtex_scene::shard::SHARD_HELP)]
pub struct GenerateArgs {
    #[arg(long, default_value = "full", conflicts_with = "config",
        help = format!("Built-in variant: {}", Config::variant_list()))]
    variant: String,
    /// A variant config file (JSON, like those in `configs/`) instead of `--variant`.
    #[arg(long, value_name = "FILE")]
    config: Option<PathBuf>,
    /// Number of images.
    #[arg(short = 'n', long = "count", value_name = "N")]
    count: u64,
    /// Run seed: with the image index it fixes every random draw.
    #[arg(long, default_value_t = 0)]
    seed: u64,
    /// First image index; images `START..START+N` are made.
    #[arg(long, default_value_t = 0, value_name = "I")]
    start: u64,
    /// Size of the whole dataset, which fixes the splits (first 10% test, next 10% val, rest
    /// train) [default: START + N].
    #[arg(long, value_name = "T")]
    total: Option<u64>,
    /// Make only the images with `index % N == K` (0 <= K < N), as `clevrtex sample` does:
    /// N shards together make every image exactly once.
    #[arg(long, value_name = "K/N")]
    shard: Option<String>,
    /// Number of shards when the shard index comes from JOB_COMPLETION_INDEX.
    #[arg(long, value_name = "N", env = "CLEVRTEX_SHARD_COUNT")]
    shard_count: Option<u64>,
    /// Image width in pixels (default 320).
    #[arg(long)]
    width: Option<u32>,
    /// Image height in pixels (default 240).
    #[arg(long)]
    height: Option<u32>,
    /// Cycles samples per pixel (default from the config).
    #[arg(long)]
    samples: Option<u32>,
    /// Samples of the shadow pass's render (default: three eighths of the samples, at most
    /// 64; RMSE ~0.018 at 8, ~0.010 at 16, ~0.008 at 24; docs/performance.md, "Shadow pass").
    #[arg(long, value_name = "N")]
    shadow_samples: Option<u32>,
    /// Quality preset: draft, standard, high or reference (samples, adaptive threshold,
    /// bounces; see docs/performance.md). `--samples` still overrides the sample count.
    #[arg(long, value_name = "PRESET")]
    quality: Option<clevrtex_scene::quality::Quality>,
    /// Layout attempts per image when objects are hidden, before the image fails.
    #[arg(long, default_value_t = 20, value_name = "N")]
    max_attempts: u32,
    #[command(flatten)]
    run: RunArgs,
}

/// Layouts drawn by `generate` before any Blender starts, to refuse impossible configs.
const PREFLIGHT_LAYOUTS: usize = 20;

/// Run `clevrtex generate`.
pub fn run_generate(args: GenerateArgs) -> CmdResult {
    let mut config = match &args.config {
        Some(path) => {
            let text = std::fs::read_to_string(path).map_err(|e| {
                anyhow::anyhow!(
                    "cannot read config `{}`: {e}\nhint: pass an existing JSON file, e.g. one of `configs/`",
                    path.display()
                )
            })?;
            Config::from_json_str(&text, &path.display().to_string())?
        }
        None => Config::builtin(&args.variant)?,
    };
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
    positive("--max-attempts", args.max_attempts)?;
    // Fail before starting Blender when no layout could ever be drawn, as `sample` does.
    clevrtex_scene::sample::check_feasible(&config)?;
    let passes = match &args.run.passes {
        Some(list) => parse_passes(list)?,
        None => Pass::ALL.to_vec(),
    };
    config.base.passes = passes.clone();
    if args.count == 0 {
        bail!("`-n 0` asks for no images\nhint: pass the number of images, e.g. `-n 100`");
    }
    let end = args
        .start
        .checked_add(args.count)
        .context("`--start` + `-n` overflows\nhint: pass smaller numbers")?;
    let total = args.total.unwrap_or(end);
    if total < end {
        bail!("`--total {total}` is smaller than the last index + 1 (`{end}`)\nhint: pass the size of the whole dataset");
    }
    let range = clevrtex_scene::shard::resolve(args.shard.as_deref(), args.shard_count)?
        .indices(args.start, end);
    // Draw the first layouts before starting Blender: a config whose objects can never be
    // placed fails here once (exit 1), as in `sample`, not once per image into the ledger.
    for &index in range.iter().take(PREFLIGHT_LAYOUTS) {
        let req = SampleRequest {
            seed: args.seed,
            index,
            attempt: 0,
            total,
        };
        clevrtex_scene::sample(&config, &req)?;
    }
    let config = Arc::new(config);
    let variant = config.name.clone();
    let jobs: Vec<Job> = range
        .into_iter()
        .map(|index| {
            let config = Arc::clone(&config);
            let seed = args.seed;
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
        })
        .collect();
    let ledger = layout::variant_dir(&args.run.out, &variant).join("failures.jsonl");
    let shard = clevrtex_scene::shard::resolve(args.shard.as_deref(), args.shard_count)?;
    let plan = manifest::Plan {
        run: manifest::Manifest {
            variant: variant.clone(),
            seed: args.seed,
            config_hash: manifest::hash_hex(format!("{config:?}").as_bytes()),
            render: serde_json::to_value(&config.base.render).ok(),
            start: args.start,
            end,
            total,
            shard: [shard.k, shard.n],
            tool_version: env!("CARGO_PKG_VERSION").into(),
            command: std::env::args().collect(),
            ..manifest::Manifest::unfinished()
        },
        passes: passes.clone(),
        keep_exr: args.run.keep_exr,
    };
    crate::run::run_jobs(&args.run, jobs, ledger, args.max_attempts, Some(plan))
}
