//! WebDataset tar shards, as `clevrtex export` writes them: the export of a dataset
//! ([`export`]), the shard names (`<variant>-<split>-<6 digits>.tar`, [`shard_name`],
//! [`is_shard_name`]) and the writer of one shard ([`ShardWriter`]: reproducible headers, a
//! temporary name until complete).
//!
//! `OUT/<variant>-<split>-%06d.tar`, each at most `shard_size` bytes (one sample is never
//! split; a sample larger than the limit gets a shard of its own), samples in index order. In a
//! shard a sample is `<stem>.<key>` for each pass it has, the key and form from the pass
//! table (`webdataset_key`, `webdataset_form`): `png` and `albedo.png` the dataset's PNGs,
//! `mask.npy` (uint8 ids), `depth.npy` (float32 metres, background +inf), `normal.npy` and
//! `shadow.npy` arrays decoded from the PNGs ([`pass_npy`], so no colour decoder can take them
//! for colours), and `<stem>.json`, so WebDataset's key is the stem. Splits are each sample's recorded `split`
//! (else, for the published ClevrTex, the public loader's position rule:
//! [`crate::dataset::splits`], the rule of every reader). The files are those of
//! the layout (`crate::layout`): a metadata `*_filename` only says whether a pass was
//! written and must name the layout's file. Links leading out of the dataset are not followed
//! and non-regular files not read (their samples are left out and listed). Shards of an
//! earlier export into OUT that this one did not write are removed (only names of the form
//! above). Tar headers carry no time, owner or mode of the machine: the same dataset gives the
//! same bytes (and the arrays no machine-dependent byte). Each shard is written under a
//! temporary name and renamed when complete; `OUT/index.json` lists the shards and their
//! sample counts, and what each key holds.
//!
//! By concern: the export of a dataset (here), one shard's entries, names and writer
//! (`shard.rs`), a pass decoded into its `.npy` array (`npy.rs`). Everything is re-exported here.

pub(crate) mod npy;
pub(crate) mod shard;
#[cfg(test)]
mod tests;

pub use npy::*;
pub use shard::*;

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};

use crate::dataset::{Dataset, DatasetError, Kind, SampleRef, VariantDir};
use crate::layout::Split;
use clevrtex_scene::passes::WebdatasetForm;
use clevrtex_scene::Pass;
use serde_json::{json, Value};

use crate::dataset;

/// What can go wrong in an export. Shown as the command's error: the message, then (as the
/// error's source) the cause.
#[derive(Debug, thiserror::Error)]
pub enum ExportError {
    /// A file or folder could not be read, created, written or removed.
    #[error("{what}")]
    Io {
        /// What failed and what to do.
        what: String,
        /// The OS error.
        #[source]
        cause: std::io::Error,
    },
    /// A sample's metadata is not JSON.
    #[error("{what}")]
    Json {
        /// Which file, and what to do.
        what: String,
        /// The parser's error.
        #[source]
        cause: serde_json::Error,
    },
    /// Anything else, with the file and what to do.
    #[error("{0}")]
    Message(String),
    /// A shard could not be written.
    #[error(transparent)]
    Shard(#[from] ShardError),
    /// The dataset could not be opened.
    #[error(transparent)]
    Dataset(#[from] DatasetError),
    /// The stop flag was raised (Ctrl-C, SIGTERM): the shard being written was removed.
    #[error("interrupted")]
    Interrupted,
}

/// What [`export`] did.
#[derive(Debug)]
pub struct ExportReport {
    /// Samples written.
    pub samples: u64,
    /// Shards written.
    pub shards: usize,
    /// Bytes of the shards written.
    pub bytes: u64,
    /// `OUT/index.json`.
    pub index: PathBuf,
    /// Shards of an earlier export that this one did not write, removed.
    pub stale: Vec<String>,
    /// Temporary shards of killed exports removed ([`remove_dead_temporaries`]).
    pub dead_temps: Vec<String>,
    /// Files or folders not followed or not read (their samples are left out), one line each.
    pub skipped: Vec<String>,
}

/// One sample to export: its metadata and the files it becomes.
struct Sample {
    index: u64,
    /// Its position among the variant's samples with metadata (for [`dataset::splits`]).
    pos: usize,
    stem: String,
    split: Split,
    files: Vec<SampleFile>,
    /// What its passes are checked against.
    check: PassCheck,
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
) -> Result<Vec<Sample>, ExportError> {
    if let Some((dir, e)) = vd.unreadable.first() {
        return Err(ExportError::Message(format!(
            "cannot read `{}`: {e}",
            dir.display()
        )));
    }
    skipped.extend(vd.skipped_for_metadata().map(ToString::to_string));
    let found: BTreeMap<u64, &SampleRef> = vd
        .samples
        .iter()
        .filter(|s| s.has_metadata())
        .map(|s| (s.index, s))
        .collect();
    let mut out = Vec::new();
    let mut recorded = vec![None; found.len()];
    'samples: for (pos, (index, s)) in found.into_iter().enumerate() {
        let stem = s.stem.clone();
        let meta_path = s.metadata_path();
        let bytes = match ds.read(&meta_path, dataset::MAX_METADATA_BYTES) {
            Ok(b) => b,
            Err(why) => {
                skipped.push(format!("`{}` {why}", meta_path.display()));
                continue;
            }
        };
        let meta: Value = serde_json::from_slice(&bytes).map_err(|cause| ExportError::Json {
            what: format!(
                "`{}` is not valid metadata\nhint: check the dataset with `clevrtex verify`",
                meta_path.display()
            ),
            cause,
        })?;
        dataset::check_metadata(&meta, &meta_path.display().to_string()).map_err(|e| {
            ExportError::Message(format!(
                "{e}\nhint: check the dataset with `clevrtex verify`"
            ))
        })?;
        let bad = |e: dataset::MetadataError| {
            ExportError::Message(format!(
                "{e}\nhint: check the dataset with `clevrtex verify`; export takes file names from the layout, not from the metadata"
            ))
        };
        let file = meta_path.display().to_string();
        // Passes whose encoding the metadata describes (ours) become arrays by it; the mask's
        // ids are its pixels in any dataset. The published ClevrTex's other passes (another
        // encoding, not described) stay PNGs under `<pass>.png`.
        let view = dataset::MetadataView::of(&meta, &file).ok();
        let described = view.as_ref().map(|v| v.passes.clone()).unwrap_or_default();
        // Ours give the size and objects every pass is checked against; the downloaded
        // ClevrTex's metadata has no size (`check_metadata` typed its `num_objects`).
        let check = PassCheck {
            size: view.as_ref().map(|v| (v.width, v.height)),
            num_objects: view.as_ref().map_or_else(
                || meta["num_objects"].as_u64().unwrap_or(0).min(255) as usize,
                |v| v.num_objects,
            ),
        };
        let mut files: Vec<SampleFile> = dataset::listed_passes(&meta, &file, &stem)
            .map_err(bad)?
            .into_iter()
            .map(|pass| {
                let spec = pass.spec();
                let (key, npy) = match spec.webdataset_form {
                    WebdatasetForm::Npy { .. }
                        if pass == Pass::Mask || described.contains(&pass) =>
                    {
                        (spec.webdataset_key.to_string(), true)
                    }
                    WebdatasetForm::Npy { .. } => (format!("{}.png", spec.name), false),
                    WebdatasetForm::Png => (spec.webdataset_key.to_string(), false),
                };
                SampleFile {
                    key,
                    path: s.pass_path(pass),
                    pass: Some(pass),
                    npy,
                }
            })
            .collect();
        if files.is_empty() {
            return Err(ExportError::Message(format!(
                "`{file}` lists no pass (no `*_filename` key names a file): the sample has nothing to export\nhint: check the dataset with `clevrtex verify`"
            )));
        }
        recorded[pos] = dataset::recorded_split(&meta["split"], &vd.variant, &file).map_err(bad)?;
        files.push(SampleFile {
            key: "json".into(),
            path: meta_path,
            pass: None,
            npy: false,
        });
        for SampleFile { path: p, .. } in &files {
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
            std::fs::metadata(p).map_err(|cause| ExportError::Io {
                what: format!(
                    "`{}` (a pass the metadata of `{stem}` lists) is missing\nhint: check the dataset with `clevrtex verify`",
                    p.display()
                ),
                cause,
            })?;
        }
        out.push(Sample {
            index,
            pos,
            split: Split::Train,
            stem,
            files,
            check,
        });
    }
    // The one split rule of every reader: the recorded split, else by position.
    let splits = dataset::splits(&vd.variant, &recorded);
    for s in &mut out {
        s.split = splits[s.pos];
    }
    Ok(out)
}

fn io_err(what: String) -> impl FnOnce(std::io::Error) -> ExportError {
    move |cause| ExportError::Io { what, cause }
}

/// Export the dataset under `dir` (an output folder of `clevrtex generate`) as WebDataset
/// shards of at most `shard_size` bytes into `out` (created if missing), the variant `variant`
/// only or every variant found. Stops between samples when `stop` is raised
/// ([`ExportError::Interrupted`]; the shard being written is removed).
pub fn export(
    dir: &Path,
    out: &Path,
    variant: Option<&str>,
    shard_size: u64,
    stop: &AtomicBool,
) -> Result<ExportReport, ExportError> {
    let ds = Dataset::open(dir).map_err(|e| match e {
        DatasetError::Unreadable { cause, .. } => ExportError::Io {
            what: format!("cannot read `{}`", dir.display()),
            cause,
        },
        other => other.into(),
    })?;
    // Shards written into the dataset would become stray files of it (and a later export of
    // it would pack nothing new): refused, as `preview` and `report` refuse an `--out` there.
    let existing = out
        .ancestors()
        .find(|p| p.exists())
        .unwrap_or(Path::new("."));
    if existing
        .canonicalize()
        .is_ok_and(|o| o.starts_with(&ds.root))
    {
        return Err(ExportError::Message(format!(
            "`{}` is inside the dataset `{}`: its shards would become files of the dataset\nhint: export into a folder outside the dataset",
            out.display(),
            dir.display()
        )));
    }
    let mut skipped = Vec::new();
    let wanted = |v: &str| variant.is_none_or(|want| want == v);
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
        return Err(ExportError::Message(format!(
            "no `clevrtex_<variant>` folder{} in `{}`\nhint: pass the `--out` folder of `clevrtex generate`",
            variant.map(|v| format!(" for `{v}`")).unwrap_or_default(),
            dir.display()
        )));
    }
    std::fs::create_dir_all(out).map_err(io_err(format!("cannot create `{}`", out.display())))?;
    refuse_foreign_shards(out)?;
    let dead_temps = remove_dead_temporaries(out)?;
    let mut index = Vec::new();
    let mut total_bytes = 0u64;
    let mut total_samples = 0u64;
    let mut written = BTreeSet::new();
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
                if stop.load(Ordering::SeqCst) {
                    return Err(ExportError::Interrupted);
                }
                // A sample whose passes fail the checks of every reader is left out, named.
                let entries = match sample_entries(&ds.root, &s.files, &s.check) {
                    Ok(e) => e,
                    Err(ShardError::Refused(why)) => {
                        skipped.push(format!("{why} (sample `{}` left out)", s.stem));
                        continue;
                    }
                    Err(e) => return Err(e.into()),
                };
                let size = tar_bytes(&entries);
                if shard
                    .as_ref()
                    .is_some_and(|w| w.samples() > 0 && w.bytes() + size > shard_size)
                {
                    let done = shard.take().unwrap().finish()?;
                    total_bytes += done["bytes"].as_u64().unwrap_or(0);
                    index.push(json!({"variant": variant, "split": split, "shard": done}));
                }
                if shard.is_none() {
                    let name = shard_name(variant, split, n);
                    written.insert(name.clone());
                    n += 1;
                    shard = Some(ShardWriter::create(out.join(name))?);
                }
                shard.as_mut().unwrap().add(s.index, &s.stem, &entries)?;
                total_samples += 1;
            }
            if let Some(w) = shard {
                let done = w.finish()?;
                total_bytes += done["bytes"].as_u64().unwrap_or(0);
                index.push(json!({"variant": variant, "split": split, "shard": done}));
            }
        }
    }
    let stale = remove_stale(out, &written)?;
    let shards = index.len();
    let doc = json!({
        "format": "webdataset",
        "source": dir.display().to_string(),
        "samples": total_samples,
        "shards": index,
        "keys": std::iter::once(json!({"key": "__key__", "holds": "the sample's stem"}))
            .chain(Pass::ALL.map(|p| json!({"key": p.spec().webdataset_key, "holds": p.spec().webdataset_doc})))
            .chain([json!({"key": "json", "holds": "the sample's metadata (docs/output-format.md)"})])
            .collect::<Vec<_>>(),
    });
    let index_path = out.join("index.json");
    let text = serde_json::to_string_pretty(&doc).expect("JSON values serialise") + "\n";
    crate::atomic::write(&index_path, text.as_bytes())
        .map_err(io_err(format!("cannot write `{}`", index_path.display())))?;
    Ok(ExportReport {
        samples: total_samples,
        shards,
        bytes: total_bytes,
        index: index_path,
        stale,
        dead_temps,
        skipped,
    })
}

/// Remove the temporary shards that killed exports left in `out`, and only those it can prove
/// are: a regular file named `<shard name>.<host>.<pid>.<start>.clevrtex-tmp` (the one atomic
/// writer's owner tag, [`crate::atomic::owner_tag`]) whose host is this one and whose process
/// is gone, empty or starting with a tar header. A live export's temporaries, another
/// host's, untagged names and anything else are left alone.
fn remove_dead_temporaries(out: &Path) -> Result<Vec<String>, ExportError> {
    let mut removed = Vec::new();
    for e in std::fs::read_dir(out)
        .map_err(io_err(format!("cannot read `{}`", out.display())))?
        .flatten()
    {
        let name = e.file_name().to_string_lossy().into_owned();
        let Some(stem) = name.strip_suffix(crate::layout::TMP_SUFFIX) else {
            continue;
        };
        let mut parts = stem.rsplitn(4, '.');
        let (Some(start), Some(pid), Some(host), Some(shard)) =
            (parts.next(), parts.next(), parts.next(), parts.next())
        else {
            continue;
        };
        let proven = is_shard_name(shard)
            && host == crate::atomic::hostname()
            && start.parse::<u64>().is_ok()
            && pid.parse::<u32>().is_ok()
            && crate::atomic::tagged_name_is_stale(stem)
            && e.file_type().is_ok_and(|t| t.is_file())
            && (e.metadata().is_ok_and(|m| m.len() == 0) || is_tar(&e.path()));
        if proven {
            std::fs::remove_file(e.path()).map_err(io_err(format!(
                "cannot remove `{}`, a temporary shard of a killed export\nhint: remove it by hand",
                e.path().display()
            )))?;
            removed.push(name);
        }
    }
    Ok(removed)
}

/// Files in `out` named like shards that no export wrote (not a tar file, or not a regular
/// file): refused before anything is written, since export replaces and removes files of
/// those names. Links named like shards are replaced or removed themselves, never followed.
fn refuse_foreign_shards(out: &Path) -> Result<(), ExportError> {
    for e in std::fs::read_dir(out)
        .map_err(io_err(format!("cannot read `{}`", out.display())))?
        .flatten()
    {
        let name = e.file_name().to_string_lossy().into_owned();
        if !is_shard_name(&name) || e.file_type().is_ok_and(|t| t.is_symlink()) {
            continue;
        }
        if !e.file_type().is_ok_and(|t| t.is_file()) || !is_tar(&e.path()) {
            return Err(ExportError::Message(format!(
                "`{}` is named like a shard but is not a tar file an export wrote: export would replace or remove it\nhint: move it out of `{}`, or export into an empty folder",
                e.path().display(),
                out.display()
            )));
        }
    }
    Ok(())
}

/// Whether `path` starts with a POSIX tar header (`ustar` at byte 257), as shards do.
fn is_tar(path: &Path) -> bool {
    use std::io::Read;
    let mut head = [0u8; 262];
    std::fs::File::open(path)
        .and_then(|mut f| f.read_exact(&mut head))
        .is_ok_and(|()| &head[257..262] == b"ustar")
}

/// Shards of an earlier export into `out` that this one did not write (fewer samples, another
/// variant): removed, so `index.json` and the shards on disk agree. Only export's own shard
/// names are touched.
fn remove_stale(out: &Path, written: &BTreeSet<String>) -> Result<Vec<String>, ExportError> {
    let mut stale = Vec::new();
    for e in std::fs::read_dir(out)
        .map_err(io_err(format!("cannot read `{}`", out.display())))?
        .flatten()
    {
        let name = e.file_name().to_string_lossy().into_owned();
        let file = e.file_type().is_ok_and(|t| t.is_file() || t.is_symlink());
        if file && is_shard_name(&name) && !written.contains(&name) {
            std::fs::remove_file(e.path()).map_err(io_err(format!(
                "cannot remove the stale shard `{}` of an earlier export\nhint: remove it by hand, or export into an empty folder",
                e.path().display()
            )))?;
            stale.push(name);
        }
    }
    Ok(stale)
}
