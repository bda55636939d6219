//! What every export (`webdataset`, `coco`) reads of a dataset, through the one dataset
//! reader ([`crate::dataset`]): the dataset opened and the variants chosen, an output folder
//! inside the dataset refused ([`open_source`]); the samples of one variant in index order with
//! their split (the one rule, [`dataset::splits`]) and the files they become ([`samples`]); and
//! the errors of an export ([`ExportError`]).

use std::collections::BTreeMap;
use std::path::Path;

use crate::dataset::{self, Dataset, DatasetError, Kind, SampleRef, VariantDir};
use crate::layout::Split;
use clevrtex_scene::passes::WebdatasetForm;
use clevrtex_scene::Pass;
use serde_json::Value;

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
    /// A shard could not be written (a `webdataset::ShardError`, kept as the source chain).
    #[error(transparent)]
    Shard(Box<dyn std::error::Error + Send + Sync>),
    /// The dataset could not be opened.
    #[error(transparent)]
    Dataset(#[from] DatasetError),
    /// The stop flag was raised (Ctrl-C, SIGTERM): the shard being written was removed.
    #[error("interrupted")]
    Interrupted,
}

/// One file of a sample in an export.
#[derive(Debug, Clone)]
pub struct SampleFile {
    /// Its key (the extension after the stem).
    pub key: String,
    /// Its path in the dataset.
    pub path: std::path::PathBuf,
    /// The pass it is (a PNG checked by [`dataset::check_pass_png`] before it is exported);
    /// `None`: the metadata.
    pub pass: Option<Pass>,
    /// Whether it becomes the pass's `.npy` array (else its bytes are packed).
    pub npy: bool,
}

/// What a sample's passes are checked against ([`dataset::check_pass_png`]): the metadata's
/// image size (`None` for the downloaded ClevrTex, whose metadata has none: the passes must
/// then agree with each other) and number of objects.
#[derive(Debug, Clone, Copy, Default)]
pub struct PassCheck {
    /// `render.width`, `render.height`.
    pub size: Option<(u32, u32)>,
    /// `num_objects`.
    pub num_objects: usize,
}

impl PassCheck {
    /// The pass `bytes` of the file `name` checked as every reader checks it
    /// ([`dataset::check_pass_png`]) and decoded; `Err` says what is wrong (the sample is then
    /// left out of every export, named). Without a size in the metadata, the first pass
    /// checked sets the size of the others (`self.size` is filled in).
    pub fn check(
        &mut self,
        name: &str,
        bytes: &[u8],
        pass: Pass,
    ) -> Result<crate::png::DecodedPng, String> {
        let png = dataset::check_pass_png(name, bytes, pass, self.size, self.num_objects)?;
        self.size.get_or_insert((png.width, png.height));
        Ok(png)
    }
}

/// One sample to export: its metadata and the files it becomes.
pub struct Sample {
    /// The sample's index.
    pub index: u64,
    /// Its position among the variant's samples with metadata (for [`dataset::splits`]).
    pub(crate) pos: usize,
    /// Its stem.
    pub stem: String,
    /// Its split (the one rule).
    pub split: Split,
    /// The files it becomes.
    pub files: Vec<SampleFile>,
    /// What its passes are checked against.
    pub check: PassCheck,
}

/// The samples of one variant folder of `ds` (found by [`Dataset::open`]), in index order,
/// and what was not followed or not read (samples with such files are left out).
/// File names come from the layout and the pass table, never from the metadata: a
/// `*_filename` key only says whether the pass was written, and must name the layout's file
/// ([`dataset::listed_passes`]).
pub fn samples(
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
    // A dataset `generate` made (its variant folder has run manifests): exactly what
    // `verify` refuses is left out, named: its check of every sample (files against the
    // manifests, metadata re-derived, mask against metadata, recorded split) and every index
    // found more than once. Without manifests (the downloaded ClevrTex, whose metadata
    // `verify` cannot vouch for) the readers' checks below are all there is.
    let mut refused: BTreeMap<(std::path::PathBuf, String), String> = BTreeMap::new();
    let verdict = if vd.manifests.is_empty() {
        crate::verify::VariantReport::default()
    } else {
        crate::verify::verify_variant(&vd.variant, &[(ds, vd)])
    };
    refused.extend(
        verdict
            .broken
            .iter()
            .map(|b| ((b.dir.clone(), b.stem.clone()), b.problems.join("; "))),
    );
    for (index, places) in &verdict.duplicates {
        for s in vd.samples.iter().filter(|s| s.index == *index) {
            refused.insert(
                (s.dir.clone(), s.stem.clone()),
                format!("index {index} is found {} times", places.len()),
            );
        }
    }
    let found: BTreeMap<u64, &SampleRef> = vd
        .samples
        .iter()
        .filter(|s| s.has_metadata())
        .filter(|s| match refused.get(&(s.dir.clone(), s.stem.clone())) {
            Some(why) => {
                skipped.push(format!(
                    "sample `{}` is refused by `clevrtex verify`: {}",
                    s.stem,
                    clevrtex_scene::text::printable(why)
                ));
                false
            }
            None => true,
        })
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

pub(crate) fn io_err(what: String) -> impl FnOnce(std::io::Error) -> ExportError {
    move |cause| ExportError::Io { what, cause }
}

/// The dataset under `dir` opened for an export into `out`: the indices (into
/// `Dataset::variants`) of the variant `variant` only or of every variant found, and what was
/// not followed (one line each). Refused before anything is written: `out` inside the dataset,
/// no variant folder (for `variant`).
pub fn open_source(
    dir: &Path,
    out: &Path,
    variant: Option<&str>,
) -> Result<(Dataset, Vec<usize>, Vec<String>), ExportError> {
    let ds = Dataset::open(dir).map_err(|e| match e {
        DatasetError::Unreadable { cause, .. } => ExportError::Io {
            what: format!("cannot read `{}`", dir.display()),
            cause,
        },
        other => other.into(),
    })?;
    // Files written into the dataset would become stray files of it (and a later export of
    // it would pack them): refused, resolved as the file system will (the one output check).
    crate::out_path::check(out, "OUT", &[dir]).map_err(ExportError::Message)?;
    let mut skipped = Vec::new();
    let wanted = |v: &str| variant.is_none_or(|want| want == v);
    // A `clevrtex_<variant>` folder given itself is not an output folder: nothing under it.
    let variants: Vec<usize> = if ds.is_variant_dir {
        Vec::new()
    } else {
        for (v, skip) in &ds.skipped {
            if wanted(v) {
                skipped.push(skip.to_string());
            }
        }
        (0..ds.variants.len())
            .filter(|&i| wanted(&ds.variants[i].variant))
            .collect()
    };
    if variants.is_empty() {
        return Err(ExportError::Message(format!(
            "no `clevrtex_<variant>` folder{} in `{}`\nhint: pass the `--out` folder of `clevrtex generate`",
            variant.map(|v| format!(" for `{v}`")).unwrap_or_default(),
            dir.display()
        )));
    }
    Ok((ds, variants, skipped))
}

/// The warning of an export that skipped `skipped` (each said to be `why`), for stderr; `None`
/// when nothing was skipped (the export is then whole).
pub fn skipped_text(skipped: &[impl std::fmt::Display], why: &str) -> Option<String> {
    if skipped.is_empty() {
        return None;
    }
    let mut text = format!(
        "warning: {} file(s) or folder(s) {why}; their samples are not exported:\n",
        skipped.len()
    );
    for s in skipped {
        text += &format!("  {s}\n");
    }
    Some(text + "hint: check the dataset with `clevrtex verify`")
}
