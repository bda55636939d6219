//! `clevrtex export --format webdataset DIR OUT`: the dataset as WebDataset tar shards, to
//! stream into training.
//!
//! `OUT/<variant>-<split>-%06d.tar`, each at most `--shard-size` bytes (one sample is never
//! split; a sample larger than the limit gets a shard of its own), samples in index order. In a
//! shard a sample is the files `<stem>.png`, `<stem>.flat.png`, `<stem>.depth.png`,
//! `<stem>.normal.png`, `<stem>.albedo.png`, `<stem>.shadow.png` (the passes it has) and
//! `<stem>.json`, so WebDataset's key is the stem. Splits come from each sample's metadata
//! (`split`, the public loader's rule; only `test`, `val` or `train`). The files are those of
//! the layout (`clevrtex_scene::layout`): a metadata `*_filename` only says whether a pass was
//! written and must name the layout's file. Links leading out of the dataset are not followed
//! and non-regular files not read (their samples are left out, exit 3). Shards of an earlier
//! export into OUT that this one did not write are removed (only names of the form above). Tar headers carry no time, owner or mode of the
//! machine: the same dataset gives the same bytes. Each shard is written under a temporary
//! name and renamed when complete; `OUT/index.json` lists the shards and their sample counts.

use std::collections::BTreeMap;
use std::io::Write;
use std::path::PathBuf;

use anyhow::{bail, Context};
use clevrtex_render::webdataset::{is_shard_name, shard_name, ShardWriter};
use clevrtex_scene::dataset::{self, Dataset, DatasetError, Kind, SampleRef, VariantDir};
use clevrtex_scene::layout::Split;
use clevrtex_scene::Pass;
use serde_json::{json, Value};

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
    /// Largest shard in bytes (a sample is never split).
    #[arg(long, default_value_t = 1_000_000_000, value_name = "BYTES")]
    shard_size: u64,
}

/// The extension of a pass in a WebDataset sample (after the stem and a dot): `png` for the
/// image, `flat.png` for the mask (its suffix in the published layout), `<pass>.png` otherwise.
fn extension(pass: Pass) -> String {
    pass.spec().webdataset_key.into()
}

/// One sample to export: its metadata and the (extension, path) of each file.
struct Sample {
    index: u64,
    stem: String,
    split: Split,
    files: Vec<(String, PathBuf)>,
    bytes: u64,
}

/// The samples of one variant folder of `ds` (found by [`Dataset::open`]), in index order,
/// and what was not followed or not read (samples with such files are left out).
/// File names come from the layout and the pass table, never from the metadata: a
/// `*_filename` key only says whether the pass was written, and must name the layout's file
/// ([`dataset::listed_passes`]).
fn samples(
    ds: &Dataset,
    vd: &VariantDir,
    skipped: &mut Vec<String>,
) -> anyhow::Result<Vec<Sample>> {
    if let Some((dir, e)) = vd.unreadable.first() {
        return Err(anyhow::anyhow!("{e}").context(format!("cannot read `{}`", dir.display())));
    }
    skipped.extend(vd.skipped_for_metadata().map(ToString::to_string));
    let found: BTreeMap<u64, &SampleRef> = vd
        .samples
        .iter()
        .filter(|s| s.has_metadata())
        .map(|s| (s.index, s))
        .collect();
    let mut out = Vec::new();
    'samples: for (index, s) in found {
        let stem = s.stem.clone();
        let meta_path = s.metadata_path();
        let bytes = match ds.read(&meta_path, dataset::MAX_METADATA_BYTES) {
            Ok(b) => b,
            Err(why) => {
                skipped.push(format!("`{}` {why}", meta_path.display()));
                continue;
            }
        };
        let meta: Value = serde_json::from_slice(&bytes).with_context(|| {
            format!(
                "`{}` is not valid metadata\nhint: check the dataset with `clevrtex verify`",
                meta_path.display()
            )
        })?;
        let bad = |e: dataset::MetadataError| {
            anyhow::anyhow!(
                "{e}\nhint: check the dataset with `clevrtex verify`; export takes file names from the layout, not from the metadata"
            )
        };
        let file = meta_path.display().to_string();
        let mut files: Vec<(String, PathBuf)> = dataset::listed_passes(&meta, &file, &stem)
            .map_err(bad)?
            .into_iter()
            .map(|pass| (extension(pass), s.pass_path(pass)))
            .collect();
        let split = dataset::split_of(&meta, &file).map_err(bad)?;
        files.push(("json".into(), meta_path));
        let mut bytes = 0;
        for (_, p) in &files {
            match ds.classify(p) {
                Kind::File => {}
                Kind::Skipped(why) => {
                    skipped.push(format!("`{}` {why}", p.display()));
                    continue 'samples;
                }
                Kind::Dir => {
                    skipped.push(format!("`{}` is a folder", p.display()));
                    continue 'samples;
                }
            }
            bytes += std::fs::metadata(p)
                .with_context(|| {
                    format!(
                        "`{}` (a pass the metadata of `{stem}` lists) is missing\nhint: check the dataset with `clevrtex verify`",
                        p.display()
                    )
                })?
                .len()
                + 1024;
        }
        out.push(Sample {
            index,
            split,
            stem,
            files,
            bytes,
        });
    }
    Ok(out)
}

/// Run `clevrtex export`.
pub fn run(args: Args) -> CmdResult {
    let Format::Webdataset = args.format;
    if args.shard_size < 10_240 {
        bail!(
            "`--shard-size {}` is too small\nhint: give at least 10240 bytes (default 1000000000)",
            args.shard_size
        );
    }
    if !args.dir.is_dir() {
        bail!(
            "`{}` is not a folder\nhint: pass the `--out` folder of `clevrtex generate`",
            args.dir.display()
        );
    }
    let ds = Dataset::open(&args.dir).map_err(|e| match e {
        DatasetError::Unreadable { cause, .. } => {
            anyhow::Error::new(cause).context(format!("cannot read `{}`", args.dir.display()))
        }
        other => other.into(),
    })?;
    let mut skipped = Vec::new();
    let wanted = |v: &str| args.variant.as_ref().is_none_or(|want| want == v);
    // A `clevrtex_<variant>` folder given itself is not an output folder: nothing under it.
    let variants: Vec<&VariantDir> = if ds.is_variant_dir {
        Vec::new()
    } else {
        for (v, skip) in &ds.skipped {
            if wanted(v) {
                skipped.push(skip.to_string());
            }
        }
        ds.variants
            .iter()
            .filter(|vd| wanted(&vd.variant))
            .collect()
    };
    if variants.is_empty() {
        bail!(
            "no `clevrtex_<variant>` folder{} in `{}`\nhint: pass the `--out` folder of `clevrtex generate`",
            args.variant.as_ref().map(|v| format!(" for `{v}`")).unwrap_or_default(),
            args.dir.display()
        );
    }
    std::fs::create_dir_all(&args.out)
        .with_context(|| format!("cannot create `{}`", args.out.display()))?;
    // Ctrl-C / SIGTERM: stop between samples; the shard being written is removed (Drop).
    let stop = crate::interrupt::flag(crate::interrupt::OnInterrupt::FlagOnly);
    let started = std::time::Instant::now();
    let mut index = Vec::new();
    let mut total_bytes = 0u64;
    let mut total_samples = 0u64;
    let mut written = std::collections::BTreeSet::new();
    for vd in &variants {
        let variant = &vd.variant;
        let all = samples(&ds, vd, &mut skipped)?;
        let mut by_split: BTreeMap<&str, Vec<&Sample>> = BTreeMap::new();
        for s in &all {
            by_split.entry(s.split.name()).or_default().push(s);
        }
        for (split, list) in by_split {
            let mut shard: Option<ShardWriter> = None;
            let mut n = 0;
            for s in list {
                if stop.load(std::sync::atomic::Ordering::SeqCst) {
                    return Err(exit::Interrupted.into());
                }
                if shard
                    .as_ref()
                    .is_some_and(|w| w.samples() > 0 && w.bytes() + s.bytes > args.shard_size)
                {
                    let done = shard.take().unwrap().finish()?;
                    total_bytes += done["bytes"].as_u64().unwrap_or(0);
                    index.push(json!({"variant": variant, "split": split, "shard": done}));
                }
                if shard.is_none() {
                    let name = shard_name(variant, split, n);
                    written.insert(name.clone());
                    let path = args.out.join(name);
                    n += 1;
                    shard = Some(ShardWriter::create(path)?);
                }
                shard
                    .as_mut()
                    .unwrap()
                    .add(&ds.root, s.index, &s.stem, &s.files)?;
                total_samples += 1;
            }
            if let Some(w) = shard {
                let done = w.finish()?;
                total_bytes += done["bytes"].as_u64().unwrap_or(0);
                index.push(json!({"variant": variant, "split": split, "shard": done}));
            }
        }
    }
    // Shards of an earlier export into OUT that this one did not write (fewer samples, another
    // variant): removed, so `index.json` and the shards on disk agree. Only export's own shard
    // names are touched.
    let mut stale = Vec::new();
    for e in std::fs::read_dir(&args.out)
        .with_context(|| format!("cannot read `{}`", args.out.display()))?
        .flatten()
    {
        let name = e.file_name().to_string_lossy().into_owned();
        let file = e.file_type().is_ok_and(|t| t.is_file() || t.is_symlink());
        if file && is_shard_name(&name) && !written.contains(&name) {
            std::fs::remove_file(e.path()).with_context(|| {
                format!(
                    "cannot remove the stale shard `{}` of an earlier export\nhint: remove it by hand, or export into an empty folder",
                    e.path().display()
                )
            })?;
            stale.push(name);
        }
    }
    if !stale.is_empty() {
        eprintln!(
            "removed {} shard(s) of an earlier export that this one did not write: {}",
            stale.len(),
            stale.join(", ")
        );
    }
    let doc = json!({
        "format": "webdataset",
        "source": args.dir.display().to_string(),
        "samples": total_samples,
        "shards": index,
        "keys": std::iter::once("__key__ = stem")
            .chain(Pass::ALL.map(|p| p.spec().webdataset_key))
            .chain(["json"])
            .collect::<Vec<_>>(),
    });
    let index_path = args.out.join("index.json");
    let tmp = args.out.join("index.json.clevrtex-tmp");
    let mut f = std::fs::File::create(&tmp)
        .with_context(|| format!("cannot create `{}`", tmp.display()))?;
    f.write_all((serde_json::to_string_pretty(&doc)? + "\n").as_bytes())
        .and_then(|()| f.sync_all())
        .and_then(|()| std::fs::rename(&tmp, &index_path))
        .with_context(|| format!("cannot write `{}`", index_path.display()))?;
    let secs = started.elapsed().as_secs_f64();
    println!(
        "exported {total_samples} samples into {} shard(s) under `{}` ({:.1} MB in {secs:.1} s, {:.0} MB/s); index: {}",
        doc["shards"].as_array().map_or(0, Vec::len),
        args.out.display(),
        total_bytes as f64 / 1e6,
        total_bytes as f64 / 1e6 / secs.max(1e-9),
        index_path.display()
    );
    if !skipped.is_empty() {
        eprintln!(
            "warning: {} file(s) or folder(s) not followed or not read; their samples are not exported:",
            skipped.len()
        );
        for s in &skipped {
            eprintln!("  {s}");
        }
        eprintln!("hint: check the dataset with `clevrtex verify`");
        return Ok(exit::PARTIAL);
    }
    Ok(exit::OK)
}
