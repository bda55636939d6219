//! A dataset as the Python `Dataset` sees it: its samples of a split, the name tables of its
//! variant and the pass table, and its files read by the one dataset reader
//! (`clevrtex_dataset::dataset`: checked against the dataset's folder, capped, never a FIFO).

use std::path::Path;

use clevrtex_eval::dataset::discover_gt;
use clevrtex_eval::{read, Split};
use clevrtex_scene::Pass;
use pyo3::exceptions::PyOSError;
use pyo3::prelude::*;
use pyo3::types::PyBytes;

use crate::errors::{eval_error, read_error, value_error};

/// The samples of a dataset in the published layout: `(variant, [(index, image, mask, meta)])`
/// for one split (`test`, `val`, `train`, `all`; test-only variants have `test` = all).
#[pyfunction]
#[pyo3(signature = (path, variant=None, split="test"))]
#[allow(clippy::type_complexity)]
pub(crate) fn discover(
    py: Python<'_>,
    path: &str,
    variant: Option<&str>,
    split: &str,
) -> PyResult<(String, Vec<(u64, String, String, String)>)> {
    let split = match split {
        "test" => Split::Test,
        "val" => Split::Val,
        "train" => Split::Train,
        "all" => Split::All,
        other => {
            return Err(value_error(format!(
                "unknown split `{other}`; known: test, val, train, all"
            )))
        }
    };
    py.allow_threads(|| {
        let (variant, mut samples) = discover_gt(Path::new(path), variant).map_err(eval_error)?;
        // As the public loader: a test-only variant is read whole, whatever the split.
        let split = if is_test_only(&variant) {
            Split::All
        } else {
            split
        };
        // Each sample's split is the one its metadata records (the one rule of every reader,
        // `clevrtex_dataset::dataset::splits`); an empty split is an error naming the sizes.
        if split.part().is_some() {
            clevrtex_eval::dataset::read_splits(Path::new(path), &variant, &mut samples)
                .map_err(eval_error)?;
        }
        let chosen = split.select(&samples, &variant).map_err(eval_error)?;
        if chosen.is_empty() {
            return Err(value_error(format!(
                "the `{}` split of `{path}` is empty: it has {} samples in all ({})\nhint: pick a split that has samples, or `split=\"all\"`",
                split.name(),
                samples.len(),
                clevrtex_eval::dataset::split_sizes(&samples)
            )));
        }
        let s = |p: &Path| p.display().to_string();
        let list = chosen
            .iter()
            .map(|x| (x.index, s(&x.image), s(&x.mask), s(&x.meta)))
            .collect();
        Ok((variant, list))
    })
}

/// Whether a variant's objects are plain-coloured, so that its metadata and results carry
/// their colour (the variant config's property, `Config::colour_breakdown`: `vbg`, `clevr`).
#[pyfunction]
pub(crate) fn colour_breakdown(variant: &str) -> bool {
    clevrtex_dataset::layout::variant_colour_breakdown(variant)
}

/// A variant with only a test split (its config says `"splits": "test_only"`, e.g. `outd`).
fn is_test_only(variant: &str) -> bool {
    clevrtex_dataset::layout::variant_splits(variant) == clevrtex_scene::config::Splits::TestOnly
}

/// The bytes of the dataset's file `p`, read by the dataset reader (`clevrtex_dataset::dataset`):
/// a regular file only (a FIFO never blocks), at most `cap` bytes, and, with `root` (the
/// dataset's canonical folder), not a link swapped in that leads out of the dataset.
fn read_checked(root: Option<&Path>, p: &str, cap: u64) -> PyResult<Vec<u8>> {
    use clevrtex_dataset::dataset::{classify, read_beneath, read_regular, Kind};
    if let Some(root) = root {
        if let Kind::Skipped(why) = classify(root, Path::new(p)) {
            if !why.starts_with("cannot be read") {
                return Err(value_error(format!(
                    "`{p}` {}",
                    why.replace("; skipped", "; not read")
                )));
            }
        }
    }
    match root {
        // Opened relative to the root's handle: a folder swapped for a link out of the dataset
        // since `discover` is not read through.
        Some(root) => read_beneath(root, Path::new(p), cap),
        None => read_regular(Path::new(p), cap),
    }
    .map_err(|e| read_error(p, e))
}

/// The dataset's folder, resolved (links inside it are followed, none out of it).
pub(crate) fn canonical_root(root: Option<&str>) -> PyResult<Option<std::path::PathBuf>> {
    root.map(|r| {
        Path::new(r)
            .canonicalize()
            .map_err(|e| PyOSError::new_err(format!("`{r}` cannot be read: {e}")))
    })
    .transpose()
}

/// A dataset's PNG, its header's size checked before it is decoded (a 1 MB mask can declare
/// 30000x30000: 4.5 GB decoded).
pub(crate) fn dataset_png(root: Option<&Path>, p: &str) -> PyResult<Vec<u8>> {
    let bytes = read_checked(root, p, clevrtex_dataset::dataset::MAX_FILE_BYTES)?;
    read::png_size_of_dataset_image(&bytes)
        .map_err(|r| value_error(format!("cannot decode `{p}`: {r}")))?;
    Ok(bytes)
}

/// Every pass's file suffix after the stem (`<stem><suffix>.png`) and metadata key, from the
/// pass table: `{name: (suffix, metadata_key)}`.
#[pyfunction]
pub(crate) fn pass_files() -> Vec<(&'static str, &'static str, &'static str)> {
    Pass::ALL
        .iter()
        .map(|p| (p.name(), p.spec().file_suffix, p.metadata_key()))
        .collect()
}

/// The name tables of a variant for ids a model can use: `(shapes, sizes as (name, scale),
/// materials of objects and ground, colours)`, in the built-in config's order (materials
/// sorted), then the user materials (`--materials DIR`) that the run manifests of the dataset
/// at `root` record, sorted, after the built-in ones (so built-in ids do not move). `None` for
/// a variant that is not built in and records no user material.
#[pyfunction]
#[pyo3(signature = (variant, root=None))]
#[allow(clippy::type_complexity)]
pub(crate) fn variant_names(
    py: Python<'_>,
    variant: &str,
    root: Option<&str>,
) -> PyResult<Option<(Vec<String>, Vec<(String, f64)>, Vec<String>, Vec<String>)>> {
    let user: Vec<String> = match root {
        Some(r) => py
            .allow_threads(|| clevrtex_dataset::fingerprint::user_materials(Path::new(r), variant))
            .map_err(|e| value_error(format!("`{r}`: {e}")))?
            .into_keys()
            .collect(),
        None => Vec::new(),
    };
    let Ok(c) = clevrtex_scene::config::Config::builtin(variant) else {
        return Ok((!user.is_empty()).then(|| (Vec::new(), Vec::new(), user, Vec::new())));
    };
    let t = c.name_tables();
    let mut materials = t.material;
    for u in user {
        if !materials.contains(&u) {
            materials.push(u);
        }
    }
    Ok(Some((t.shape, t.size, materials, t.color)))
}

/// The dataset's one id table (`clevrtex_dataset::ids`, docs/output-format.md "Ids"): `(shapes,
/// sizes, materials, colours)`, the built-in names in their fixed order, then the user
/// materials that any run manifest of the dataset at `root` records, sorted. The same ids as
/// the WebDataset and COCO exports of the dataset (their `ids.json`).
#[pyfunction]
#[allow(clippy::type_complexity)]
pub(crate) fn id_tables(
    py: Python<'_>,
    root: &str,
) -> PyResult<(Vec<String>, Vec<String>, Vec<String>, Vec<String>)> {
    let t = py
        .allow_threads(|| clevrtex_dataset::ids::IdTables::of_dataset(Path::new(root)))
        .map_err(|e| value_error(format!("`{root}`: {e}")))?;
    Ok((t.shape, t.size, t.material, t.color))
}

/// A sample's metadata, read as every reader of a dataset reads it
/// (`clevrtex_dataset::dataset`): checked again when read, so that a link swapped in after
/// `discover` that leads out of the dataset `root` is not followed; a regular file opened
/// non-blocking, at most 64 MiB, and checked as the CLI checks it
/// (`clevrtex_dataset::dataset::check_metadata`). `ValueError` naming the file when it is not
/// read or not valid, `OSError`
/// (its subclass by errno: `FileNotFoundError`, `PermissionError`) when it cannot be opened.
#[pyfunction]
pub(crate) fn read_metadata<'py>(
    py: Python<'py>,
    path: &str,
    root: &str,
) -> PyResult<Bound<'py, PyBytes>> {
    use clevrtex_dataset::dataset::{classify, read_beneath, Kind, ReadError};
    let p = Path::new(path);
    let read = py.allow_threads(|| {
        let root = Path::new(root).canonicalize().map_err(ReadError::Io)?;
        if let Kind::Skipped(why) = classify(&root, p) {
            if !why.starts_with("cannot be read") {
                return Ok(Err(format!(
                    "`{path}` {}",
                    why.replace("; skipped", "; not read")
                )));
            }
        }
        // Opened relative to the root's handle: a folder on the way swapped for a link out of
        // the dataset is not read through.
        match read_beneath(&root, p, clevrtex_eval::dataset::MAX_METADATA_BYTES) {
            Err(ReadError::LeadsOut) => Ok(Err(format!("`{path}` {}", ReadError::LeadsOut))),
            // The CLI's checks of a sample's metadata (types and bounds of `num_objects`,
            // `objects`, `split`, the size, ...), one rule for every reader.
            Ok(bytes) => {
                Ok(clevrtex_dataset::dataset::check_metadata_bytes(&bytes, path).map(|()| bytes))
            }
            Err(e) => Err(e),
        }
    });
    match read {
        Ok(Ok(bytes)) => Ok(PyBytes::new(py, &bytes)),
        Ok(Err(why)) => Err(value_error(why)),
        // OSError(errno, message, filename) is the subclass of its errno.
        Err(ReadError::Io(e)) => Err(PyOSError::new_err((
            e.raw_os_error().unwrap_or(0),
            format!("`{path}` cannot be read: {e}"),
            path.to_string(),
        ))),
        Err(ReadError::NotRegular) => Err(value_error(format!(
            "`{path}` is not a regular file (a FIFO, socket or device); not read"
        ))),
        Err(e @ ReadError::LeadsOut) => Err(value_error(format!("`{path}` {e}"))),
        Err(ReadError::TooLarge { len, cap }) => Err(value_error(format!(
            "`{path}` {}, over the {cap} bytes read of a sample's metadata; not read",
            len.map_or("grew".to_string(), |n| format!("is {n} bytes"))
        ))),
    }
}
