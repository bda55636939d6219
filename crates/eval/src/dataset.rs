//! Finding ground-truth samples (the published layout) and the predictions that go with them.

use std::collections::{BTreeMap, HashMap};
use std::path::{Path, PathBuf};

use clevrtex_dataset::layout::{self, parse_stem};
use clevrtex_scene::config::Splits;
use rayon::prelude::*;

use crate::error::EvalError;

/// One ground-truth sample: `CLEVRTEX_<variant>_<index:06>{.png,_flat.png,.json}`.
#[derive(Clone, Debug, PartialEq)]
pub struct GtSample {
    /// Numeric index.
    pub index: u64,
    /// File stem, `CLEVRTEX_<variant>_<index:06>`.
    pub stem: String,
    /// The RGB image.
    pub image: PathBuf,
    /// The instance mask (`_flat.png`).
    pub mask: PathBuf,
    /// The metadata.
    pub meta: PathBuf,
    /// The dataset's canonical root: the files above are opened relative to it
    /// ([`GtSample::read`]), so a folder swapped for a link out of it is not read through.
    pub root: PathBuf,
    /// Its split: the one its metadata records, else (the published ClevrTex) the public
    /// loader's position rule ([`clevrtex_dataset::dataset::splits`]); `None` until
    /// [`read_splits`] (a whole dataset needs no split, and reads no metadata to open).
    pub split: Option<layout::Split>,
}

impl GtSample {
    /// The bytes of `path` (one of this sample's files), at most `cap`, opened relative to the
    /// dataset's root ([`clevrtex_dataset::dataset::read_beneath`]).
    pub fn read(&self, path: &Path, cap: u64) -> Result<Vec<u8>, EvalError> {
        clevrtex_dataset::dataset::read_beneath(&self.root, path, cap).map_err(|why| {
            EvalError::Io {
                path: path.to_path_buf(),
                cause: why.into_io(),
            }
        })
    }
}

/// Which samples to evaluate: a split ([`GtSample::split`]) or all.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Split {
    /// The first `int(0.1 N)`.
    Test,
    /// The next `int(0.2 N) - int(0.1 N)`.
    Val,
    /// The rest.
    Train,
    /// Every sample.
    All,
}

impl Split {
    /// The dataset layout's split this one is, `None` for [`Split::All`].
    pub fn part(self) -> Option<layout::Split> {
        match self {
            Split::Test => Some(layout::Split::Test),
            Split::Val => Some(layout::Split::Val),
            Split::Train => Some(layout::Split::Train),
            Split::All => None,
        }
    }

    /// Name as on the command line.
    pub fn name(self) -> &'static str {
        self.part().map_or("all", layout::Split::name)
    }

    /// The samples of this split among `samples` (each with its [`GtSample::split`]); a
    /// variant whose config says `"splits": "test_only"` (`outd`) has only a test split.
    pub fn select<'a>(
        self,
        samples: &'a [GtSample],
        variant: &str,
    ) -> Result<Vec<&'a GtSample>, EvalError> {
        let Some(part) = self.part() else {
            return Ok(samples.iter().collect());
        };
        if layout::variant_splits(variant) == Splits::TestOnly && part != layout::Split::Test {
            return Err(EvalError::Usage {
                message: format!(
                    "`{variant}` is a test-only dataset, it has no `{}` split",
                    self.name()
                ),
                hint: "use `--split test` (the default) or `--split all`".into(),
            });
        }
        Ok(samples.iter().filter(|s| s.split == Some(part)).collect())
    }
}

/// How many of `samples` are in each split, for messages: `test 0, val 0, train 4`.
pub fn split_sizes(samples: &[GtSample]) -> String {
    let splits: Vec<layout::Split> = samples.iter().filter_map(|s| s.split).collect();
    clevrtex_dataset::dataset::split_sizes(&splits)
}

/// Every regular file under `dir`, recursively and depth-limited, walked with the reader of
/// untrusted folders (`clevrtex_dataset::dataset`): links are followed only inside `dir`, and
/// FIFOs, sockets and devices are left out.
pub fn walk(dir: &Path) -> Result<Vec<PathBuf>, EvalError> {
    Ok(walk_noting_skipped(dir)?.0)
}

/// Entries a walk left out, each with the reason (`is a FIFO ...`).
pub type Skipped = Vec<(PathBuf, String)>;

/// [`walk`], and the entries it left out.
pub fn walk_noting_skipped(dir: &Path) -> Result<(Vec<PathBuf>, Skipped), EvalError> {
    let root = clevrtex_dataset::dataset::root(dir).map_err(|cause| EvalError::Io {
        path: dir.to_path_buf(),
        cause,
    })?;
    let mut out = Vec::new();
    let mut skipped = Vec::new();
    let mut seen = std::collections::HashSet::new();
    walk_into(&root, dir, 0, &mut out, &mut skipped, &mut seen)?;
    out.sort();
    Ok((out, skipped))
}

fn walk_into(
    root: &Path,
    dir: &Path,
    depth: usize,
    out: &mut Vec<PathBuf>,
    skipped: &mut Skipped,
    seen: &mut std::collections::HashSet<PathBuf>,
) -> Result<(), EvalError> {
    use clevrtex_dataset::dataset::{list, Kind};
    // Symlinked directories are followed once each, so a link cycle cannot blow up the walk.
    if !seen.insert(std::fs::canonicalize(dir).unwrap_or_else(|_| dir.to_path_buf())) {
        return Ok(());
    }
    let entries = list(root, dir).map_err(|cause| EvalError::Io {
        path: dir.to_path_buf(),
        cause,
    })?;
    for (_, path, kind) in entries {
        match kind {
            Kind::Dir if depth < NOTED_DEPTH => {
                walk_into(root, &path, depth + 1, out, skipped, seen)?
            }
            // Too deep to read: named, so that a prediction there is not just "missing".
            Kind::File if depth > MAX_WALK_DEPTH => skipped.push((
                path,
                format!("lies more than {MAX_WALK_DEPTH} folders deep; not read (move it up)"),
            )),
            Kind::File => out.push(path),
            Kind::Skipped(why) => skipped.push((path, why)),
            _ => {}
        }
    }
    Ok(())
}

/// Folders below the walked one that are read (files deeper are named, not read).
pub const MAX_WALK_DEPTH: usize = 32;
/// Folders below the walked one whose files are named as too deep; deeper, nothing is listed.
const NOTED_DEPTH: usize = 2 * MAX_WALK_DEPTH;

/// Largest input file read (a prediction `.npz` of 1024 soft masks at 1024x1024 fits).
pub const MAX_FILE_BYTES: u64 = clevrtex_dataset::dataset::MAX_FILE_BYTES;

/// The bytes of an input file found by [`walk`]: a regular file (never a FIFO, which would
/// block), at most [`MAX_FILE_BYTES`].
pub fn read_file(path: &Path) -> Result<Vec<u8>, EvalError> {
    clevrtex_dataset::dataset::read_regular(path, MAX_FILE_BYTES).map_err(|why| EvalError::Io {
        path: path.to_path_buf(),
        cause: why.into_io(),
    })
}

/// Largest ground-truth metadata file read (a sample's JSON is a few KB; the CLI's other
/// readers of a dataset's metadata stop at the same size).
pub const MAX_METADATA_BYTES: u64 = 64 << 20;

/// The bytes of a ground-truth metadata file found by [`discover_gt`], like [`read_file`] but
/// at most [`MAX_METADATA_BYTES`].
pub fn read_metadata(path: &Path) -> Result<Vec<u8>, EvalError> {
    clevrtex_dataset::dataset::read_regular(path, MAX_METADATA_BYTES).map_err(|why| EvalError::Io {
        path: path.to_path_buf(),
        cause: why.into_io(),
    })
}

fn file_name(p: &Path) -> &str {
    p.file_name().and_then(|n| n.to_str()).unwrap_or("")
}

/// Find the ground-truth samples under `dir` (a dataset: its `clevrtex_<variant>` folders, or
/// one of them, walked by [`clevrtex_dataset::dataset::Dataset::open`]), sorted by index.
/// Without `variant`, the directory must hold exactly one variant. Gaps in the index sequence
/// and duplicate stems are errors, as are samples missing their mask or metadata.
pub fn discover_gt(
    dir: &Path,
    variant: Option<&str>,
) -> Result<(String, Vec<GtSample>), EvalError> {
    use clevrtex_dataset::dataset::{Dataset, DatasetError};
    use clevrtex_scene::Pass;
    if !dir.is_dir() {
        return Err(EvalError::not_a_dir(dir));
    }
    let ds = Dataset::open(dir).map_err(|e| match e {
        DatasetError::Unreadable { cause, .. } => EvalError::Io {
            path: dir.to_path_buf(),
            cause,
        },
        DatasetError::NotAFolder { .. } => EvalError::not_a_dir(dir),
    })?;
    let mut by_variant: BTreeMap<
        String,
        Vec<(u64, String, PathBuf, &clevrtex_dataset::dataset::SampleRef)>,
    > = BTreeMap::new();
    // A sample is any stem with an image, a mask or metadata: one whose image is missing (or
    // not read) is an error below, not left out (that would shift the splits, taken by
    // position).
    for s in ds.variants.iter().flat_map(|vd| &vd.samples) {
        if s.has_pass(Pass::Rgb) || s.has_pass(Pass::Mask) || s.has_metadata() {
            by_variant.entry(s.variant.clone()).or_default().push((
                s.index,
                s.stem.clone(),
                s.pass_path(Pass::Rgb),
                s,
            ));
        }
    }
    let pattern = format!("CLEVRTEX_{}_??????.png", variant.unwrap_or("<variant>"));
    let (variant, mut found) = match variant {
        Some(v) => match by_variant.remove(v) {
            Some(found) => (v.to_string(), found),
            None => {
                return Err(EvalError::NoSamples {
                    dir: dir.to_path_buf(),
                    pattern,
                })
            }
        },
        None => {
            if by_variant.len() > 1 {
                return Err(EvalError::SeveralVariants {
                    dir: dir.to_path_buf(),
                    variants: by_variant.into_keys().collect(),
                });
            }
            match by_variant.pop_first() {
                Some(x) => x,
                None => {
                    return Err(EvalError::NoSamples {
                        dir: dir.to_path_buf(),
                        pattern,
                    })
                }
            }
        }
    };
    found.sort_by(|a, b| (a.0, &a.1, &a.2).cmp(&(b.0, &b.1, &b.2)));
    for w in found.windows(2) {
        if w[0].0 == w[1].0 {
            return Err(EvalError::Duplicate {
                what: "ground-truth sample",
                stem: w[0].1.clone(),
                a: w[0].2.clone(),
                b: w[1].2.clone(),
            });
        }
        if w[1].0 != w[0].0 + 1 {
            return Err(EvalError::GtGap {
                missing: w[0].0 + 1,
                first: found[0].0,
                last: found[found.len() - 1].0,
                count: found.len(),
            });
        }
    }
    // A sample's image, mask and metadata must be among the files the walk found: a link out
    // of the folder, a FIFO or a device in their place is refused, not read.
    let mut samples = Vec::with_capacity(found.len());
    for (index, stem, image, s) in found {
        let mask = s.pass_path(Pass::Mask);
        let meta = s.metadata_path();
        for (p, ok) in [
            (&image, s.has_pass(Pass::Rgb)),
            (&mask, s.has_pass(Pass::Mask)),
            (&meta, s.has_metadata()),
        ] {
            if ok {
                continue;
            }
            if std::fs::symlink_metadata(p).is_ok() {
                if let clevrtex_dataset::dataset::Kind::Skipped(why) = ds.classify(p) {
                    // The walk's reason ends in "skipped" where a reader goes on without the
                    // file; the evaluation stops instead (exit 1), so it is not said here.
                    let why = why.trim_end_matches("; skipped").to_string();
                    return Err(EvalError::GtNotRead {
                        stem,
                        path: p.clone(),
                        why,
                    });
                }
            }
            return Err(EvalError::GtIncomplete {
                stem,
                path: p.clone(),
            });
        }
        samples.push(GtSample {
            index,
            stem,
            image,
            mask,
            meta,
            root: ds.root.clone(),
            split: None,
        });
    }
    Ok((variant, samples))
}

/// Set each sample's [`GtSample::split`] (the samples of one variant of the dataset `gt`, as
/// [`discover_gt`] found them, in index order): the split its metadata records, only that key
/// read (in parallel), else by position (the one rule of `clevrtex_dataset::dataset::splits`).
pub fn read_splits(gt: &Path, variant: &str, samples: &mut [GtSample]) -> Result<(), EvalError> {
    let root = clevrtex_dataset::dataset::root(gt).map_err(|cause| EvalError::Io {
        path: gt.to_path_buf(),
        cause,
    })?;
    let recorded = samples
        .par_iter()
        .map(|s| {
            clevrtex_dataset::dataset::read_recorded_split(&root, &s.meta, variant).map_err(
                |reason| EvalError::Corrupt {
                    path: s.meta.clone(),
                    reason,
                    hint: "a sample's `split` is `test`, `val` or `train` (absent in the published ClevrTex); check the dataset with `clevrtex verify`".into(),
                },
            )
        })
        .collect::<Result<Vec<_>, _>>()?;
    for (s, split) in samples
        .iter_mut()
        .zip(clevrtex_dataset::dataset::splits(variant, &recorded))
    {
        s.split = Some(split);
    }
    Ok(())
}

/// The prediction files found for one stem.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct PredFiles {
    /// `<stem>_mask.png`, `<stem>.npy` or `<stem>.npz`.
    pub segmentation: Option<PathBuf>,
    /// `<stem>_recon.png`.
    pub recon: Option<PathBuf>,
    /// A segmentation file of this stem that was not read, and why (a link out of the
    /// folder, a FIFO): named when the stem has no prediction.
    pub skipped: Option<String>,
}

/// Index the prediction files under `dir` by stem, for the stems of `variant`. Two
/// segmentation files for one stem (e.g. in two folders, or both `.npy` and `_mask.png`) are an
/// error naming both.
pub fn index_preds(dir: &Path, variant: &str) -> Result<HashMap<String, PredFiles>, EvalError> {
    if !dir.is_dir() {
        return Err(EvalError::not_a_dir(dir));
    }
    let mut out: HashMap<String, PredFiles> = HashMap::new();
    let (files, skipped) = walk_noting_skipped(dir)?;
    for (f, why) in skipped {
        let name = file_name(&f);
        let stem = ["_mask.png", ".npy", ".npz"]
            .iter()
            .find_map(|s| parse_stem(name, s))
            .map(|(stem, _, _)| stem.to_string());
        if let Some(stem) = stem.filter(|s| s.starts_with(&format!("CLEVRTEX_{variant}_"))) {
            let note = format!(
                "`{}` {why}",
                clevrtex_scene::text::printable(&f.display().to_string())
            );
            out.entry(stem).or_default().skipped = Some(note);
        }
    }
    for f in files {
        let name = file_name(&f);
        let (stem, is_recon) = if let Some((stem, _, _)) = parse_stem(name, "_recon.png") {
            (stem, true)
        } else if let Some((stem, _, _)) = ["_mask.png", ".npy", ".npz"]
            .iter()
            .find_map(|s| parse_stem(name, s))
        {
            (stem, false)
        } else {
            continue;
        };
        if !stem.starts_with(&format!("CLEVRTEX_{variant}_")) {
            continue;
        }
        let entry = out.entry(stem.to_string()).or_default();
        let slot = if is_recon {
            &mut entry.recon
        } else {
            &mut entry.segmentation
        };
        if let Some(prev) = slot {
            return Err(EvalError::Duplicate {
                what: "prediction",
                stem: stem.to_string(),
                a: prev.clone(),
                b: f.clone(),
            });
        }
        *slot = Some(f.clone());
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn symlink_cycles_are_walked_once() {
        let d = tempfile::tempdir().unwrap();
        std::fs::create_dir(d.path().join("a")).unwrap();
        std::fs::write(d.path().join("a/f.txt"), b"x").unwrap();
        #[cfg(unix)]
        {
            std::os::unix::fs::symlink(d.path(), d.path().join("a/up")).unwrap();
            std::os::unix::fs::symlink(d.path(), d.path().join("a/up2")).unwrap();
        }
        let files = walk(d.path()).unwrap();
        assert_eq!(files.len(), 1, "{files:?}");
    }

    #[test]
    fn splits_select_by_each_sample_s_split() {
        let sample = |index: u64, split| GtSample {
            index,
            stem: layout::stem("full", index),
            image: PathBuf::new(),
            mask: PathBuf::new(),
            meta: PathBuf::new(),
            root: PathBuf::new(),
            split: Some(split),
        };
        let v = [
            sample(0, layout::Split::Test),
            sample(1, layout::Split::Val),
            sample(2, layout::Split::Train),
            sample(3, layout::Split::Val),
        ];
        let idx = |s: Split| -> Vec<u64> {
            s.select(&v, "full")
                .unwrap()
                .iter()
                .map(|x| x.index)
                .collect()
        };
        assert_eq!(idx(Split::Val), [1, 3]);
        assert_eq!(idx(Split::All).len(), 4);
        assert_eq!(split_sizes(&v), "test 1, val 2, train 1");
        assert!(Split::Val.select(&v, "outd").is_err());
    }
}
