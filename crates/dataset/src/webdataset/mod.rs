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
//! `shadow.npy` arrays decoded from the PNGs ([`decoded_npy`], so no colour decoder can take them
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
//! sample counts, and what each key holds; `OUT/ids.json` the dataset's one id table
//! ([`crate::ids`]), which the ids of `--objects K` index.
//!
//! By concern: the export of a dataset (here), one shard's entries, names and writer
//! (`shard.rs`), a pass decoded into its `.npy` array (`npy.rs`). Everything is re-exported here.

pub(crate) mod npy;
pub(crate) mod record;
pub(crate) mod shard;
#[cfg(test)]
mod tests;
pub(crate) mod transform;

pub use npy::*;
pub use record::*;
pub use shard::*;
pub use transform::*;

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};

use crate::dataset::VariantDir;
pub use crate::export::ExportError;
use crate::export::{io_err, samples, Sample};
use clevrtex_scene::Pass;
use serde_json::{json, Value};

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

/// Export the dataset under `dir` (an output folder of `clevrtex generate`) as WebDataset
/// shards of at most `shard_size` bytes into `out` (created if missing), the variant `variant`
/// only or every variant found, with the per-object arrays padded to `objects` when given
/// ([`object_arrays`]), cropped (and resized) as the public loader does with `crop`
/// ([`crop_resize`]: `Some(None)` the crop, `Some(Some(side))` the crop resized). Stops between samples when `stop` is raised
/// ([`ExportError::Interrupted`]; the shard being written is removed).
pub fn export(
    dir: &Path,
    out: &Path,
    variant: Option<&str>,
    shard_size: u64,
    objects: Option<usize>,
    crop: Option<Option<usize>>,
    stop: &AtomicBool,
) -> Result<ExportReport, ExportError> {
    let (ds, chosen, mut skipped) = crate::export::open_source(dir, out, variant)?;
    let variants: Vec<&VariantDir> = chosen.iter().map(|&i| &ds.variants[i]).collect();
    let names: Vec<&str> = variants.iter().map(|v| v.variant.as_str()).collect();
    // The dataset's one id table (`crate::ids`): the same integers as the Python `Dataset`
    // and the COCO export give, whichever variants are exported; names outside it (a dataset
    // someone else made) are added at the end, in the order found.
    let mut tables = crate::ids::IdTables::of_dataset(dir).map_err(ExportError::Message)?;
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
                let mut entries = match sample_entries(&ds.root, &s.files, &s.check) {
                    Ok(e) => e,
                    Err(ShardError::Refused(why)) => {
                        skipped.push(format!("{why} (sample `{}` left out)", s.stem));
                        continue;
                    }
                    Err(e) => return Err(e.into()),
                };
                let frame = match crop {
                    None => None,
                    Some(side) => Some(crop_resize(&mut entries, &s.files, side).map_err(|w| {
                        ExportError::Message(format!(
                            "sample `{}`: {w}\nhint: check the dataset with `clevrtex verify`",
                            s.stem
                        ))
                    })?),
                };
                let extra = sample_record(s, variant, &mut entries, objects, frame, &mut tables)?;
                entries.extend(extra);
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
    let mut keys: Vec<Value> = std::iter::once(json!({"key": "__key__", "holds": "the sample's stem"}))
        .chain(Pass::ALL.map(|p| json!({"key": p.spec().webdataset_key, "holds": p.spec().webdataset_doc})))
        .chain([json!({"key": "json", "holds": "the sample's record, one schema for every variant: stem, variant, split, index, num_objects, ground_material, objects (shape, size, material, color, rotation, coords_3d, pixel_coords, visible_pixels, bbox; \"\", -1 or [] where a sample lacks one), intrinsics, extrinsics, and `metadata`: the metadata file's text (docs/output-format.md)"})])
        .collect();
    if let Some(k) = objects {
        keys.extend(OBJECT_KEYS.iter().map(
            |(key, holds)| json!({"key": key, "holds": holds.replace("K", &format!("K = {k}"))}),
        ));
    }
    let doc = json!({
        "format": "webdataset",
        "source": dir.display().to_string(),
        "samples": total_samples,
        "shards": index,
        "keys": keys,
        "objects": objects,
        "names": objects.map(|_| tables.names_json()),
        "ids": "ids.json",
        "crop": crop.is_some(),
        "resize": crop.flatten(),
    });
    // The id table beside the shards, with or without `--objects`.
    let ids_path = out.join("ids.json");
    let ids_text = serde_json::to_string_pretty(&tables.to_json(&names))
        .expect("JSON values serialise")
        + "\n";
    crate::atomic::write(&ids_path, ids_text.as_bytes())
        .map_err(io_err(format!("cannot write `{}`", ids_path.display())))?;
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

impl From<ShardError> for ExportError {
    fn from(e: ShardError) -> ExportError {
        ExportError::Shard(Box::new(e))
    }
}

/// The per-object keys of `--objects K` and what each holds.
pub const OBJECT_KEYS: [(&str, &str); 7] = [
    ("shape.npy", "int64 (K,) shape ids into `names.shape`; -1 for padding"),
    ("size.npy", "int64 (K,) size ids into `names.size`; -1 for padding"),
    ("material.npy", "int64 (K,) material ids into `names.material`; -1 for padding"),
    ("color.npy", "int64 (K,) colour ids into `names.color`; -1 for padding and where the variant has no colours"),
    ("bbox.npy", "float32 (K, 4) [x_min, y_min, x_max, y_max], inclusive pixels of the object in mask.npy; 0 where not visible"),
    ("visibility.npy", "bool (K,) the object has a pixel in mask.npy"),
    ("valid.npy", "bool (K,) slot k holds an object (k < num_objects)"),
];

/// The sample's `json` in `entries` replaced by its [`record`] (in the crop's `frame` when
/// cropped); with `objects` = `Some(K)`, its per-object arrays ([`object_arrays`], from the
/// entries' `mask.npy`), returned to be added.
fn sample_record(
    s: &Sample,
    variant: &str,
    entries: &mut [(String, Vec<u8>)],
    objects: Option<usize>,
    frame: Option<Frame>,
    tables: &mut crate::ids::IdTables,
) -> Result<Vec<(String, Vec<u8>)>, ExportError> {
    let Some(json) = entries.iter_mut().find(|(k, _)| k == "json") else {
        return Ok(Vec::new());
    };
    let meta_bytes = std::mem::take(&mut json.1);
    json.1 = record(&meta_bytes, variant, s.split, s.index, &s.stem, frame);
    let Some(k) = objects else {
        return Ok(Vec::new());
    };
    let meta_path = s
        .files
        .iter()
        .find(|f| f.key == "json")
        .map(|f| f.path.clone())
        .unwrap_or_default();
    let bad = |why: String| {
        ExportError::Message(format!(
            "`{}` {why}\nhint: check the dataset with `clevrtex verify`",
            meta_path.display()
        ))
    };
    let Some((_, mask)) = entries.iter().find(|(k, _)| k == "mask.npy") else {
        return Err(ExportError::Message(format!(
            "sample `{}` has no mask pass: `--objects` needs the mask\nhint: generate with `--passes` including mask, or leave `--objects` out",
            s.stem
        )));
    };
    let (shape, start) =
        npy_shape(mask).ok_or_else(|| bad("has a mask that is not an array".into()))?;
    let ids: Vec<u16> = mask[start..].iter().map(|&v| u16::from(v)).collect();
    let meta: Value = serde_json::from_slice(&meta_bytes).unwrap_or(Value::Null);
    object_arrays(&meta, &ids, shape[1], k, tables).map_err(bad)
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
