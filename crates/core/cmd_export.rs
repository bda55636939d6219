//! `clevrtex export --format webdataset DIR OUT`: the dataset as WebDataset tar shards, to
//! stream into training. The export is `clevrtex_dataset::webdataset::export` (the layout of
//! the shards is documented there and in docs/output-format.md); this parses and prints.

use std::path::PathBuf;

use anyhow::bail;
use clevrtex_dataset::webdataset::{export, ExportError};

use crate::exit::{self, CmdResult};

/// Output formats.
#[derive(Debug, Clone, Copy, clap::ValueEnum)]
pub enum Format {
    /// Tar shards for the `webdataset` library.
    Webdataset,
}

/// Arguments of `clevrtex export`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// Output format.
    #[arg(long, value_enum, default_value = "webdataset")]
    format: Format,
    /// The dataset: an output folder of `clevrtex generate` (`--out`).
    #[arg(value_name = "DIR")]
    dir: PathBuf,
    /// Where the shards go (created if missing).
    #[arg(value_name = "OUT")]
    out: PathBuf,
    /// Export only this variant (default: every variant found).
    #[arg(long)]
    variant: Option<String>,
    /// Largest shard in bytes (a sample is never split), 10240 to 10^12.
    #[arg(long, default_value_t = 1_000_000_000, value_name = "BYTES", value_parser = clap::builder::RangedU64ValueParser::<u64>::new().range(10_240..=1_000_000_000_000))]
    shard_size: u64,
}

/// Run `clevrtex export`.
pub fn run(args: Args) -> CmdResult {
    let Format::Webdataset = args.format;
    if !args.dir.is_dir() {
        bail!(
            "`{}` is not a folder\nhint: pass the `--out` folder of `clevrtex generate`",
            args.dir.display()
        );
    }
    // Ctrl-C / SIGTERM: stop between samples; the shard being written is removed (Drop).
    let stop = crate::interrupt::flag(crate::interrupt::OnInterrupt::FlagOnly);
    let started = std::time::Instant::now();
    let r = match export(
        &args.dir,
        &args.out,
        args.variant.as_deref(),
        args.shard_size,
        &stop,
    ) {
        Ok(r) => r,
        Err(ExportError::Interrupted) => return Err(exit::Interrupted.into()),
        Err(e) => return Err(e.into()),
    };
    if !r.dead_temps.is_empty() {
        eprintln!(
            "removed {} temporary shard(s) of killed exports: {}",
            r.dead_temps.len(),
            r.dead_temps.join(", ")
        );
    }
    if !r.stale.is_empty() {
        eprintln!(
            "removed {} shard(s) of an earlier export that this one did not write: {}",
            r.stale.len(),
            r.stale.join(", ")
        );
    }
    let secs = started.elapsed().as_secs_f64();
    println!(
        "exported {} samples into {} shard(s) under `{}` ({:.1} MB in {secs:.1} s, {:.0} MB/s); index: {}",
        r.samples,
        r.shards,
        args.out.display(),
        r.bytes as f64 / 1e6,
        r.bytes as f64 / 1e6 / secs.max(1e-9),
        r.index.display()
    );
    if !r.skipped.is_empty() {
        eprintln!(
            "warning: {} file(s) or folder(s) not followed, not read or refused by the checks of every reader; their samples are not exported:",
            r.skipped.len()
        );
        for s in &r.skipped {
            eprintln!("  {s}");
        }
        eprintln!("hint: check the dataset with `clevrtex verify`");
        return Ok(exit::PARTIAL);
    }
    Ok(exit::OK)
}
