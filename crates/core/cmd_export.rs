//! `clevrtex export --format webdataset DIR OUT`: the dataset as WebDataset tar shards, to
//! stream into training; `--format coco`: COCO instances JSON per variant and split, for
//! detection and instance-segmentation code. The exports are
//! `clevrtex_dataset::webdataset::export` and `clevrtex_dataset::coco::export_coco` (their
//! layouts are documented there and in docs/output-format.md); this parses and prints.

use std::path::PathBuf;

use anyhow::bail;
use clevrtex_dataset::coco::{export_coco, CocoOptions};
use clevrtex_dataset::layout::Split;
use clevrtex_dataset::webdataset::{export, ExportError};

use crate::exit::{self, CmdResult};

/// Output formats.
#[derive(Debug, Clone, Copy, clap::ValueEnum)]
pub enum Format {
    /// Tar shards for the `webdataset` library.
    Webdataset,
    /// COCO instances JSON (RLE masks, boxes), one file per variant and split.
    Coco,
}

/// The splits `--split` takes.
#[derive(Debug, Clone, Copy, clap::ValueEnum)]
pub enum SplitArg {
    /// The test split.
    Test,
    /// The validation split.
    Val,
    /// The training split.
    Train,
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
    /// `--format webdataset`: add per-object arrays padded to K objects (ids of shape, size,
    /// material, colour; boxes; visibility), 1 to 255.
    #[arg(long, value_name = "K", value_parser = clap::builder::RangedU64ValueParser::<usize>::new().range(1..=255))]
    objects: Option<usize>,
    /// `--format webdataset`: crop every image and pass to the centre square of side
    /// int(0.8 min(W, H)), as the public loader does (`crop=True`).
    #[arg(long)]
    crop: bool,
    /// `--format webdataset`, with `--crop`: resize the crop to N x N (the public loader's
    /// 128), Pillow-exact bilinear for the image and albedo, nearest for the mask and data passes.
    #[arg(long, value_name = "N", value_parser = clap::builder::RangedU64ValueParser::<usize>::new().range(1..=4096))]
    resize: Option<usize>,
    /// `--format coco`: export only this split (default: every split, one file each).
    #[arg(long, value_enum)]
    split: Option<SplitArg>,
    /// `--format coco`: copy the images to `OUT/images/` (default: `file_name` is the image
    /// where it lies, an absolute path).
    #[arg(long)]
    copy_images: bool,
}

/// Run `clevrtex export`.
pub fn run(args: Args) -> CmdResult {
    if let Format::Coco = args.format {
        if args.objects.is_some() || args.crop || args.resize.is_some() {
            bail!("`--objects`, `--crop` and `--resize` are options of `--format webdataset`: COCO has one annotation per object at the image's own size\nhint: leave them out");
        }
        return run_coco(args);
    }
    if args.split.is_some() || args.copy_images {
        bail!("`--split` and `--copy-images` are options of `--format coco`\nhint: leave them out, or add `--format coco`");
    }
    if args.resize.is_some() && !args.crop {
        bail!("`--resize` resizes the centre crop, as the public loader does\nhint: add `--crop`");
    }
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
        args.objects,
        args.crop.then_some(args.resize),
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
            clevrtex_scene::text::printable(&r.dead_temps.join(", "))
        );
    }
    if !r.stale.is_empty() {
        eprintln!(
            "removed {} shard(s) of an earlier export that this one did not write: {}",
            r.stale.len(),
            clevrtex_scene::text::printable(&r.stale.join(", "))
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
    Ok(skipped_warning(
        &r.skipped,
        "not followed, not read or refused by the checks of every reader",
    ))
}

/// `clevrtex export --format coco`.
fn run_coco(args: Args) -> CmdResult {
    if !args.dir.is_dir() {
        bail!(
            "`{}` is not a folder\nhint: pass the `--out` folder of `clevrtex generate`",
            args.dir.display()
        );
    }
    let opts = CocoOptions {
        variant: args.variant.clone(),
        split: args.split.map(|s| match s {
            SplitArg::Test => Split::Test,
            SplitArg::Val => Split::Val,
            SplitArg::Train => Split::Train,
        }),
        copy_images: args.copy_images,
    };
    let stop = crate::interrupt::flag(crate::interrupt::OnInterrupt::FlagOnly);
    let started = std::time::Instant::now();
    let r = match export_coco(&args.dir, &args.out, &opts, &stop) {
        Ok(r) => r,
        Err(ExportError::Interrupted) => return Err(exit::Interrupted.into()),
        Err(e) => return Err(e.into()),
    };
    let secs = started.elapsed().as_secs_f64();
    for (path, images, annotations) in &r.files {
        println!(
            "wrote `{}`: {images} images, {annotations} annotations",
            path.display()
        );
    }
    println!(
        "exported {} images into {} COCO file(s) under `{}` in {secs:.1} s",
        r.files.iter().map(|f| f.1).sum::<usize>(),
        r.files.len(),
        args.out.display()
    );
    Ok(skipped_warning(&r.skipped, "not followed or not read"))
}

/// The exit code of an export that skipped `skipped` (each printed under a warning saying
/// they were `why`): `PARTIAL` when any, else `OK`.
fn skipped_warning(skipped: &[impl std::fmt::Display], why: &str) -> u8 {
    match clevrtex_dataset::export::skipped_text(skipped, why) {
        Some(text) => {
            eprintln!("{}", clevrtex_scene::text::printable_lines(&text));
            exit::PARTIAL
        }
        None => exit::OK,
    }
}
