//! `clevrtex export --format webdataset DIR OUT`: the dataset as WebDataset tar shards, to
//! stream into training.
//!
//! `OUT/<variant>-<split>-%06d.tar`, each at most `--shard-size` bytes (one sample is never
//! split; a sample larger than the limit gets a shard of its own), samples in index order. In a
//! shard a sample is the files `<stem>.png`, `<stem>.flat.png`, `<stem>.depth.png`,
//! `<stem>.normal.png`, `<stem>.albedo.png`, `<stem>.shadow.png` (the passes it has) and
//! `<stem>.json`, so WebDataset's key is the stem. Splits come from each sample's metadata
//! (`split`, the public loader's rule). Tar headers carry no time, owner or mode of the
//! machine: the same dataset gives the same bytes. Each shard is written under a temporary
//! name and renamed when complete; `OUT/index.json` lists the shards and their sample counts.

use std::collections::BTreeMap;
use std::io::Write;
use std::path::{Path, PathBuf};

use anyhow::{bail, Context};
use clevrtex_scene::{layout, Pass};
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
    match pass {
        Pass::Rgb => "png".into(),
        Pass::Mask => "flat.png".into(),
        p => format!("{}.png", p.name()),
    }
}

/// One sample to export: its metadata and the (extension, path) of each file.
struct Sample {
    index: u64,
    stem: String,
    split: String,
    files: Vec<(String, PathBuf)>,
    bytes: u64,
}

/// The samples of one variant folder, in index order.
fn samples(vdir: &Path) -> anyhow::Result<Vec<Sample>> {
    let mut found = BTreeMap::new();
    let mut subdirs: Vec<PathBuf> = std::fs::read_dir(vdir)
        .with_context(|| format!("cannot read `{}`", vdir.display()))?
        .flatten()
        .map(|e| e.path())
        .filter(|p| p.is_dir())
        .collect();
    subdirs.sort();
    for d in subdirs {
        for e in std::fs::read_dir(&d)
            .with_context(|| format!("cannot read `{}`", d.display()))?
            .flatten()
        {
            let name = e.file_name().to_string_lossy().into_owned();
            if let Some((stem, _, index)) = layout::parse_stem(&name, ".json") {
                found.insert(index, (stem.to_string(), d.clone()));
            }
        }
    }
    let mut out = Vec::new();
    for (index, (stem, dir)) in found {
        let meta_path = dir.join(layout::metadata_file(&stem));
        let meta: Value = serde_json::from_slice(
            &std::fs::read(&meta_path)
                .with_context(|| format!("cannot read `{}`", meta_path.display()))?,
        )
        .with_context(|| {
            format!(
                "`{}` is not valid metadata\nhint: check the dataset with `clevrtex verify`",
                meta_path.display()
            )
        })?;
        let mut files = Vec::new();
        for pass in Pass::ALL {
            let key = match pass {
                Pass::Rgb => "image_filename".to_string(),
                p => format!("{}_filename", p.name()),
            };
            if let Some(name) = meta[&key].as_str() {
                files.push((extension(pass), dir.join(name)));
            }
        }
        files.push(("json".into(), meta_path));
        let mut bytes = 0;
        for (_, p) in &files {
            bytes += std::fs::metadata(p)
                .with_context(|| {
                    format!(
                        "`{}` (named by the metadata of `{stem}`) is missing\nhint: check the dataset with `clevrtex verify`",
                        p.display()
                    )
                })?
                .len()
                + 1024;
        }
        out.push(Sample {
            index,
            split: meta["split"].as_str().unwrap_or("train").to_string(),
            stem,
            files,
            bytes,
        });
    }
    Ok(out)
}

/// A tar shard being written under a temporary name.
struct ShardWriter {
    tmp: PathBuf,
    path: PathBuf,
    /// `None` once finished.
    builder: Option<tar::Builder<std::io::BufWriter<std::fs::File>>>,
    bytes: u64,
    samples: u64,
    first: u64,
    last: u64,
}

impl ShardWriter {
    fn create(path: PathBuf) -> anyhow::Result<ShardWriter> {
        let tmp = path.with_extension("tar.clevrtex-tmp");
        let f = std::fs::File::create(&tmp)
            .with_context(|| format!("cannot create `{}`", tmp.display()))?;
        Ok(ShardWriter {
            tmp,
            path,
            builder: Some(tar::Builder::new(std::io::BufWriter::new(f))),
            bytes: 0,
            samples: 0,
            first: 0,
            last: 0,
        })
    }

    fn add(&mut self, s: &Sample) -> anyhow::Result<()> {
        for (ext, path) in &s.files {
            let data =
                std::fs::read(path).with_context(|| format!("cannot read `{}`", path.display()))?;
            let mut h = tar::Header::new_ustar();
            h.set_size(data.len() as u64);
            h.set_mode(0o644);
            h.set_mtime(0);
            h.set_uid(0);
            h.set_gid(0);
            h.set_entry_type(tar::EntryType::Regular);
            let name = format!("{}.{ext}", s.stem);
            self.builder
                .as_mut()
                .expect("not finished")
                .append_data(&mut h, &name, data.as_slice())
                .with_context(|| format!("cannot write `{}`", self.tmp.display()))?;
            self.bytes += 512 + (data.len() as u64).div_ceil(512) * 512;
        }
        if self.samples == 0 {
            self.first = s.index;
        }
        self.last = s.index;
        self.samples += 1;
        Ok(())
    }

    /// Finish the tar, flush it to disk and rename it to its final name.
    fn finish(mut self) -> anyhow::Result<Value> {
        let w = self
            .builder
            .take()
            .expect("finished once")
            .into_inner()
            .with_context(|| format!("cannot write `{}`", self.tmp.display()))?;
        let f = w
            .into_inner()
            .map_err(|e| e.into_error())
            .with_context(|| format!("cannot write `{}`", self.tmp.display()))?;
        f.sync_all()
            .with_context(|| format!("cannot write `{}`", self.tmp.display()))?;
        std::fs::rename(&self.tmp, &self.path)
            .with_context(|| format!("cannot write `{}`", self.path.display()))?;
        let size = std::fs::metadata(&self.path)?.len();
        Ok(json!({
            "file": self.path.file_name().unwrap().to_string_lossy(),
            "samples": self.samples,
            "bytes": size,
            "first_index": self.first,
            "last_index": self.last,
        }))
    }
}

impl Drop for ShardWriter {
    fn drop(&mut self) {
        // Unfinished (an error): leave no partial shard.
        let _ = std::fs::remove_file(&self.tmp);
    }
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
    let mut variants: Vec<(String, PathBuf)> = std::fs::read_dir(&args.dir)
        .with_context(|| format!("cannot read `{}`", args.dir.display()))?
        .flatten()
        .filter_map(|e| {
            let name = e.file_name().to_string_lossy().into_owned();
            let v = name.strip_prefix("clevrtex_")?.to_string();
            e.path().is_dir().then_some((v, e.path()))
        })
        .filter(|(v, _)| args.variant.as_ref().is_none_or(|want| want == v))
        .collect();
    variants.sort();
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
    for (variant, vdir) in &variants {
        let all = samples(vdir)?;
        let mut by_split: BTreeMap<String, Vec<&Sample>> = BTreeMap::new();
        for s in &all {
            by_split.entry(s.split.clone()).or_default().push(s);
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
                    .is_some_and(|w| w.samples > 0 && w.bytes + s.bytes > args.shard_size)
                {
                    let done = shard.take().unwrap().finish()?;
                    total_bytes += done["bytes"].as_u64().unwrap_or(0);
                    index.push(json!({"variant": variant, "split": split, "shard": done}));
                }
                if shard.is_none() {
                    let path = args.out.join(format!("{variant}-{split}-{n:06}.tar"));
                    n += 1;
                    shard = Some(ShardWriter::create(path)?);
                }
                shard.as_mut().unwrap().add(s)?;
                total_samples += 1;
            }
            if let Some(w) = shard {
                let done = w.finish()?;
                total_bytes += done["bytes"].as_u64().unwrap_or(0);
                index.push(json!({"variant": variant, "split": split, "shard": done}));
            }
        }
    }
    let doc = json!({
        "format": "webdataset",
        "source": args.dir.display().to_string(),
        "samples": total_samples,
        "shards": index,
        "keys": ["__key__ = stem", "png", "flat.png", "depth.png", "normal.png", "albedo.png", "shadow.png", "json"],
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
    Ok(exit::OK)
}
