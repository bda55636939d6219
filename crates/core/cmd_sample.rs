//! `clevrtex sample`: write one scene file per image, without rendering (the run is
//! `clevrtex_dataset::sample_run`'s).

use std::path::PathBuf;
use std::time::Instant;

use anyhow::{bail, Context};
use clevrtex_dataset::sample_run;
use clevrtex_scene::config::Config;

use crate::exit::{CmdResult, Interrupted, OK};
use crate::interrupt::{self, OnInterrupt};
use crate::run_args::{index_range, threads_range};

/// Arguments of `clevrtex sample`.
#[derive(Debug, clap::Args)]
#[command(after_help = clevrtex_scene::shard::SHARD_HELP)]
pub struct Args {
    #[arg(
        long,
        help = format!("Built-in variant: {}", Config::variant_list()),
        value_name = "NAME",
        required_unless_present = "config",
        conflicts_with = "config"
    )]
    pub variant: Option<String>,
    /// A variant config file (copy one of `configs/`); its `name` names the outputs.
    #[arg(long, value_name = "FILE")]
    pub config: Option<PathBuf>,
    /// Number of images, indices `start .. start + n`, at most 100000000 (indices stay below
    /// 100000000, the dataset cap).
    #[arg(short = 'n', long = "count", value_name = "N", value_parser = index_range())]
    pub count: u64,
    /// Run seed; with the image index it fixes every random draw.
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Draw layouts from this variant's stream instead of this variant's own (the default:
    /// the same `--seed` gives unrelated layouts in every variant). `--layout-stream full`
    /// gives e.g. `camo` the layouts of `full` (same seed): the controlled comparison of
    /// materials on one set of layouts; `shared` is the one stream every variant drew from up
    /// to clevrtex 0.1. Recorded in scene files, metadata and manifests (`layout_stream`).
    #[arg(long, value_name = "VARIANT")]
    pub layout_stream: Option<String>,
    /// Output root; files go to `<out>/clevrtex_<variant>/<index / 1000>/CLEVRTEX_<variant>_<index:06>.json`.
    #[arg(long, value_name = "DIR")]
    pub out: PathBuf,
    /// First image index.
    #[arg(long, default_value_t = 0, value_name = "I", value_parser = index_range())]
    pub start: u64,
    /// Size of the whole dataset, which fixes the splits (first 10% test, next 10% val, rest
    /// train), at most 100000000 [default: start + n].
    #[arg(long, value_name = "T", value_parser = index_range())]
    pub total: Option<u64>,
    /// Write only the indices with `index % N == K` (0 <= K < N).
    #[arg(long, value_name = "K/N")]
    pub shard: Option<String>,
    /// Number of shards when the shard index comes from JOB_COMPLETION_INDEX.
    #[arg(long, value_name = "N", env = "CLEVRTEX_SHARD_COUNT")]
    pub shard_count: Option<u64>,
    /// Worker threads, 1 to 1024 [default: one per core].
    #[arg(short = 'j', long, value_name = "N", value_parser = threads_range::<usize>())]
    pub jobs: Option<usize>,
    #[command(flatten)]
    pub materials: crate::user_materials::MaterialsArg,
    /// Draw the variant's textured materials from this set, as `generate --material-set`
    /// (default with `--materials` and a built-in `--variant`: `user`).
    #[arg(long, value_name = "SET")]
    pub material_set: Option<String>,
}

fn load_config(args: &Args) -> anyhow::Result<Config> {
    let cat = args.materials.catalogue()?;
    let mut config = read_config(args, &cat)?;
    let default_user = args.materials.materials.is_some() && args.config.is_none();
    let overrides = clevrtex_scene::config::Overrides {
        layout_stream: args.layout_stream.clone(),
        ..Default::default()
    };
    config
        .apply_material_set(&cat, args.material_set.as_deref(), default_user)
        .and_then(|()| config.apply_overrides(&overrides))
        .map_err(anyhow::Error::msg)?;
    Ok(config)
}

fn read_config(args: &Args, cat: &clevrtex_materials::Catalogue) -> anyhow::Result<Config> {
    let variant = match (&args.config, &args.variant) {
        (None, None) => {
            bail!("no variant given\nhint: pass `--variant camo` or `--config my.json`")
        }
        (_, v) => v.as_deref().unwrap_or_default(),
    };
    let hint = "check the path; built-in configs are listed in `configs/`";
    crate::run_args::read_config(args.config.as_deref(), variant, cat, hint)
}

/// Run `clevrtex sample`.
pub fn run(args: Args) -> CmdResult {
    let started = Instant::now();
    if args.count == 0 {
        bail!("`-n 0` asks for no scene file\nhint: pass the number of images to sample, e.g. `-n 100`");
    }
    let config = load_config(&args)?;
    let shard = clevrtex_scene::shard::resolve(args.shard.as_deref(), args.shard_count)?;
    let end = args.start.checked_add(args.count).with_context(|| {
        format!(
            "`--start {}` plus `-n {}` overflows",
            args.start, args.count
        )
    })?;
    clevrtex_scene::config::check_index_end(args.start, end).map_err(anyhow::Error::msg)?;
    let total = args.total.unwrap_or(end);
    if total < end {
        bail!("`--total {total}` is smaller than the last index + 1 (`{end}`)\nhint: pass the size of the whole dataset, or leave `--total` out");
    }
    // Fail before writing anything when no draw could ever succeed.
    clevrtex_scene::sample::check_feasible(&config)?;
    let progress = indicatif::ProgressBar::new(end.saturating_sub(args.start).div_ceil(shard.n));
    // Ctrl-C: finish the files being written (each appears whole or not at all) and stop.
    let interrupted = interrupt::flag(OnInterrupt::FlagOnly);
    let req = sample_run::Request {
        config: &config,
        out: &args.out,
        seed: args.seed,
        start: args.start,
        end,
        total,
        shard,
        threads: args.jobs.unwrap_or(0),
        command: std::env::args().collect(),
    };
    let result = sample_run::run(&req, &interrupted, &|| progress.inc(1));
    progress.finish_and_clear();
    let written = match result.map_err(anyhow::Error::msg)? {
        sample_run::Sampled::Done(written) => written,
        sample_run::Sampled::Interrupted => return Err(Interrupted.into()),
    };
    eprintln!(
        "wrote {} scene files (indices {}..{end}, shard {}/{}, seed {}) under `{}` in {:.2} s",
        written,
        args.start,
        shard.k,
        shard.n,
        args.seed,
        args.out.join(format!("clevrtex_{}", config.name)).display(),
        started.elapsed().as_secs_f64()
    );
    Ok(OK)
}
