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
use std::path::{Path, PathBuf};

use anyhow::{bail, Context};
use clevrtex_render::dataset::{self, Kind};
use clevrtex_scene::layout::Split;
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

/// The samples of one variant folder (under the dataset's canonical `root`), in index order,
/// and what was not followed or not read (samples with such files are left out).
/// File names come from the layout and the pass table, never from the metadata: a
/// `*_filename` key only says whether the pass was written, and must name the layout's file.
fn samples(root: &Path, vdir: &Path, skipped: &mut Vec<String>) -> anyhow::Result<Vec<Sample>> {
    let mut found = BTreeMap::new();
    let entries =
        dataset::list(root, vdir).with_context(|| format!("cannot read `{}`", vdir.display()))?;
    for (_, d, kind) in entries {
        match kind {
            Kind::Dir => {}
            Kind::Skipped(why) => {
                skipped.push(format!("`{}` {why}", d.display()));
                continue;
            }
            Kind::File => continue,
        }
        for (name, p, kind) in
            dataset::list(root, &d).with_context(|| format!("cannot read `{}`", d.display()))?
        {
            if let Some((stem, _, index)) = layout::parse_stem(&name, ".json") {
                if let Kind::Skipped(why) = kind {
                    skipped.push(format!("`{}` {why}", p.display()));
                    continue;
                }
                found.insert(index, (stem.to_string(), d.clone()));
            }
        }
    }
    let mut out = Vec::new();
    'samples: for (index, (stem, dir)) in found {
        let meta_path = dir.join(layout::metadata_file(&stem));
        let bytes = match dataset::read(root, &meta_path, dataset::MAX_FILE_BYTES) {
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
        let bad = |key: &str, what: String| {
            anyhow::anyhow!(
                "metadata `{}` key `{key}` {what}\nhint: check the dataset with `clevrtex verify`; export takes file names from the layout, not from the metadata",
                meta_path.display()
            )
        };
        let mut files = Vec::new();
        for pass in Pass::ALL {
            let key = pass.metadata_key();
            let want = layout::pass_file(&stem, pass);
            match &meta[key] {
                Value::Null => {}
                Value::String(name) if *name == want => {
                    files.push((extension(pass), dir.join(want)))
                }
                other => {
                    return Err(bad(
                        key,
                        format!("is {other}, not the layout's `{want}` (or null)"),
                    ))
                }
            }
        }
        let split = match &meta["split"] {
            Value::Null => Split::Train,
            Value::String(s) => match Split::parse(s) {
                Some(x) => x,
                None => return Err(bad("split", format!("is `{s}`, not test, val or train"))),
            },
            other => return Err(bad("split", format!("is {other}, not test, val or train"))),
        };
        files.push(("json".into(), meta_path));
        let mut bytes = 0;
        for (_, p) in &files {
            match dataset::classify(root, p) {
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

/// Whether `name` is one of export's shard names, `<variant>-<split>-<6 digits>.tar`.
fn is_shard_name(name: &str) -> bool {
    let Some(rest) = name.strip_suffix(".tar") else {
        return false;
    };
    let Some((head, digits)) = rest.rsplit_once('-') else {
        return false;
    };
    let Some((variant, split)) = head.rsplit_once('-') else {
        return false;
    };
    !variant.is_empty()
        && Split::parse(split).is_some()
        && digits.len() == 6
        && digits.bytes().all(|b| b.is_ascii_digit())
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

    fn add(&mut self, root: &Path, s: &Sample) -> anyhow::Result<()> {
        for (ext, path) in &s.files {
            let data = dataset::read(root, path, dataset::MAX_FILE_BYTES).map_err(|why| {
                anyhow::anyhow!(
                    "`{}` {why}\nhint: check the dataset with `clevrtex verify`",
                    path.display()
                )
            })?;
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
    let root = dataset::root(&args.dir)
        .with_context(|| format!("cannot read `{}`", args.dir.display()))?;
    let mut skipped = Vec::new();
    let mut variants: Vec<(String, PathBuf)> = Vec::new();
    for (name, path, kind) in dataset::list(&root, &args.dir)
        .with_context(|| format!("cannot read `{}`", args.dir.display()))?
    {
        let Some(v) = name.strip_prefix("clevrtex_") else {
            continue;
        };
        if args.variant.as_ref().is_some_and(|want| want != v) {
            continue;
        }
        match kind {
            Kind::Dir => variants.push((v.to_string(), path)),
            Kind::Skipped(why) => skipped.push(format!("`{}` {why}", path.display())),
            Kind::File => {}
        }
    }
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
    for (variant, vdir) in &variants {
        let all = samples(&root, vdir, &mut skipped)?;
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
                    .is_some_and(|w| w.samples > 0 && w.bytes + s.bytes > args.shard_size)
                {
                    let done = shard.take().unwrap().finish()?;
                    total_bytes += done["bytes"].as_u64().unwrap_or(0);
                    index.push(json!({"variant": variant, "split": split, "shard": done}));
                }
                if shard.is_none() {
                    let name = format!("{variant}-{split}-{n:06}.tar");
                    written.insert(name.clone());
                    let path = args.out.join(name);
                    n += 1;
                    shard = Some(ShardWriter::create(path)?);
                }
                shard.as_mut().unwrap().add(&root, s)?;
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
