//! Reading a dataset for the report: every sample's metadata (in parallel), the manifests and
//! the failure ledgers, found by the one read side of a dataset (`clevrtex_dataset::dataset::
//! Dataset::open`). Works on our output and on the published ClevrTex layout, whose
//! metadata lacks our keys (those come back as `None`).

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use anyhow::bail;
use clevrtex_dataset::dataset::{self as reader, DatasetError};
use clevrtex_dataset::manifest::Manifest;
use clevrtex_scene::scene_file::MAX_IMAGE_SIDE;
use indicatif::ProgressBar;
use rayon::prelude::*;
use serde_json::Value;

use super::geometry::{self, Camera};

/// One object of a sample's metadata.
#[derive(Debug, Clone)]
pub struct Object {
    pub shape: String,
    pub size: String,
    pub color: Option<String>,
    pub material: String,
    /// World position; z is the scale (objects rest on the floor).
    pub coords: [f64; 3],
    /// Visible pixels in the mask (ours only).
    pub visible_pixels: Option<u64>,
    /// Estimated share of the object hidden by others (ours only; cube, cylinder, sphere).
    pub occluded: Option<f64>,
}

/// One sample's metadata, the parts the report uses.
#[derive(Debug, Clone)]
pub struct Sample {
    pub variant: String,
    pub index: u64,
    pub stem: String,
    pub dir: PathBuf,
    /// `test`, `val` or `train`: recorded, else by position (`clevrtex_dataset::dataset::splits`).
    pub split: String,
    pub ground_material: String,
    pub objects: Vec<Object>,
    /// Accepted layout attempt = rejected layouts before it (ours only).
    pub attempt: Option<u32>,
    pub seed: Option<u64>,
    /// The layout stream of the draws (`shared`, clevrtex 0.1's, when the metadata records
    /// none; only a valid stream name is kept).
    pub layout_stream: String,
    /// Camera position (ours only).
    pub camera_location: Option<[f64; 3]>,
    pub blender_version: Option<String>,
    pub clevrtex_version: Option<String>,
    pub visibility_threshold_px: Option<u64>,
    /// Depth pass encoding `(scale in metres, background value)` (ours only).
    pub depth_encoding: Option<(f64, u16)>,
    /// Image size from the metadata's render settings (ours only).
    pub size: Option<(u32, u32)>,
}

/// A failure ledger entry.
#[derive(Debug, Clone)]
pub struct Failure {
    pub variant: String,
    pub index: u64,
    pub error: String,
}

/// A dataset read for the report.
pub struct Dataset {
    pub root: PathBuf,
    /// Samples in (variant, index) order.
    pub samples: Vec<Sample>,
    pub manifests: Vec<Manifest>,
    pub failures: Vec<Failure>,
    /// Manifests that could not be read: (path, why).
    pub bad_manifests: Vec<(PathBuf, String)>,
    /// Samples left out, one line each (`<file>: <why>`): metadata that cannot be read or is
    /// not valid, a link out of the dataset, a FIFO.
    pub problems: Vec<String>,
    /// By variant: where the recorded splits differ from the public loader's position rule
    /// over the samples read (`clevrtex_dataset::dataset::loader_disagreement`, as `verify`
    /// says it); absent where they agree.
    pub loader_splits: BTreeMap<String, String>,
}

impl Dataset {
    /// Seconds per sample from the manifests, by stem.
    pub fn sample_seconds(&self) -> BTreeMap<String, f64> {
        self.manifests
            .iter()
            .flat_map(|m| m.sample_seconds.iter().map(|(k, v)| (k.clone(), *v)))
            .collect()
    }
}

/// Read the dataset under `dir`, with a progress bar over the samples.
pub fn read(dir: &Path, bar: &ProgressBar) -> anyhow::Result<Dataset> {
    let mut found: Vec<(String, u64, String, &reader::SampleRef)> = Vec::new();
    let mut manifests = Vec::new();
    let mut bad_manifests = Vec::new();
    let mut failures = Vec::new();
    let mut problems = Vec::new();
    // The folders first: they say when the dataset does not exist.
    let hint = "hint: pass the `--out` folder of `clevrtex generate`, a `clevrtex_<variant>` folder, or the downloaded ClevrTex";
    if !dir.is_dir() {
        bail!("dataset folder `{}` does not exist\n{hint}", dir.display());
    }
    let ds = reader::Dataset::open(dir).map_err(|e| match e {
        DatasetError::Unreadable { cause, .. } => {
            anyhow::Error::new(cause).context(format!("cannot read `{}`\n{hint}", dir.display()))
        }
        other => other.into(),
    })?;
    if ds.variants.is_empty() {
        bail!(
            "no `clevrtex_<variant>` folder under `{}`\n{hint}",
            dir.display()
        );
    }
    for vd in &ds.variants {
        if let Some((p, e)) = vd.unreadable.first() {
            return Err(anyhow::anyhow!("{e}").context(format!("cannot read `{}`", p.display())));
        }
        problems.extend(vd.skipped_for_metadata().map(ToString::to_string));
        for (p, m) in vd.read_manifests() {
            match m {
                Ok(m) => manifests.push(m),
                Err(e) => bad_manifests.push((p, e)),
            }
        }
        for p in &vd.ledgers {
            for e in ds.read_ledger(p).unwrap_or_default() {
                failures.push(Failure {
                    variant: e.variant.unwrap_or_else(|| "?".into()),
                    index: e.index.unwrap_or(0),
                    error: e.error,
                });
            }
        }
        for s in vd.samples.iter().filter(|s| s.has_metadata()) {
            found.push((s.variant.clone(), s.index, s.stem.clone(), s));
        }
    }
    found.sort_by(|a, b| (&a.0, a.1, &a.2, &a.3.dir).cmp(&(&b.0, b.1, &b.2, &b.3.dir)));
    if found.is_empty() {
        bail!(
            "no samples (`CLEVRTEX_<variant>_<index>.json`) under `{}`\nhint: pass the `--out` folder of `clevrtex generate` or the downloaded ClevrTex",
            dir.display()
        );
    }
    bar.set_length(found.len() as u64);
    let read = found
        .into_par_iter()
        .map(|(variant, index, stem, s)| {
            let path = s.metadata_path();
            let dir = s.dir.clone();
            let file = path.display().to_string();
            let sample = ds
                .read_metadata(s)
                .map_err(|why| format!("`{file}` {why}"))
                .and_then(|meta| {
                    // Typed and bounded as every reader checks it (the error names the key).
                    reader::check_metadata(&meta, &file).map_err(|e| {
                        format!("`{file}` is not valid metadata: key `{}` {}", e.key, e.what)
                    })?;
                    let split =
                        reader::recorded_split(&meta["split"], &variant, &file).map_err(|e| {
                            format!("`{file}` is not valid metadata: key `split` {}", e.what)
                        })?;
                    parse(variant, index, stem, dir, &meta)
                        .map(|s| (s, split))
                        .map_err(|e| format!("`{file}` is not valid metadata: {e:#}"))
                });
            bar.inc(1);
            sample
        })
        .collect::<Vec<_>>();
    let mut samples = Vec::new();
    let mut recorded = Vec::new();
    for r in read {
        match r {
            Ok((s, split)) => {
                samples.push(s);
                recorded.push(split);
            }
            Err(p) => problems.push(p),
        }
    }
    // The one split rule of every reader (`clevrtex_dataset::dataset::splits`): the recorded
    // split, else (the published ClevrTex) the position among the variant's samples.
    let mut start = 0;
    let mut loader_splits = BTreeMap::new();
    while start < samples.len() {
        let variant = samples[start].variant.clone();
        let end = start
            + samples[start..]
                .iter()
                .take_while(|s| s.variant == variant)
                .count();
        if let Some(d) = reader::loader_disagreement(&variant, &recorded[start..end]) {
            loader_splits.insert(variant.clone(), d);
        }
        for (s, split) in samples[start..end]
            .iter_mut()
            .zip(reader::splits(&variant, &recorded[start..end]))
        {
            s.split = split.name().to_string();
        }
        start = end;
    }
    if samples.is_empty() {
        bail!(
            "no readable sample under `{}`: {}\nhint: `clevrtex verify` finds broken samples and `--remove-broken` deletes them for a rerun",
            dir.display(),
            problems.first().map(String::as_str).unwrap_or("")
        );
    }
    Ok(Dataset {
        root: dir.to_path_buf(),
        samples,
        loader_splits,
        manifests,
        failures,
        bad_manifests,
        problems,
    })
}

fn parse(
    variant: String,
    index: u64,
    stem: String,
    dir: PathBuf,
    m: &Value,
) -> anyhow::Result<Sample> {
    let Some(objs) = m["objects"].as_array() else {
        bail!("no `objects` list");
    };
    let camera = camera_of(m);
    let size = match (
        m["render"]["width"].as_u64(),
        m["render"]["height"].as_u64(),
    ) {
        (Some(w @ 1..), Some(h @ 1..)) if w.max(h) <= u64::from(MAX_IMAGE_SIDE) => {
            Some((w as u32, h as u32))
        }
        _ => None,
    };
    let objects = objs
        .iter()
        .map(|o| {
            let c = &o["3d_coords"];
            let coords = [
                c[0].as_f64().unwrap_or(f64::NAN),
                c[1].as_f64().unwrap_or(f64::NAN),
                c[2].as_f64().unwrap_or(f64::NAN),
            ];
            let shape = o["shape"].as_str().unwrap_or("?").to_string();
            let rotation = o["rotation"].as_f64().unwrap_or(0.0);
            let visible_pixels = o["visible_pixels"].as_u64();
            let occluded = match (&camera, size, visible_pixels) {
                (Some(cam), Some(wh), Some(px)) => {
                    geometry::silhouette_area(cam, wh, &shape, coords, rotation)
                        .map(|area| (1.0 - px as f64 / area.max(1.0)).clamp(0.0, 1.0))
                }
                _ => None,
            };
            Object {
                shape,
                size: o["size"].as_str().unwrap_or("?").to_string(),
                color: o["color"].as_str().map(str::to_string),
                material: o["material"].as_str().unwrap_or("?").to_string(),
                coords,
                visible_pixels,
                occluded,
            }
        })
        .collect();
    let depth = &m["passes"]["depth"];
    Ok(Sample {
        variant,
        index,
        stem,
        dir,
        // Set by `read` from the one split rule.
        split: String::new(),
        ground_material: m["ground_material"].as_str().unwrap_or("?").to_string(),
        objects,
        attempt: m["attempt"].as_u64().map(|a| a as u32),
        seed: m["seed"].as_u64(),
        layout_stream: m["layout_stream"]
            .as_str()
            .filter(|s| clevrtex_scene::names::variant_name_problem(s).is_none())
            .unwrap_or(clevrtex_scene::SHARED_STREAM)
            .to_string(),
        camera_location: camera.as_ref().map(|c| c.location),
        blender_version: m["blender_version"].as_str().map(str::to_string),
        clevrtex_version: m["clevrtex_version"].as_str().map(str::to_string),
        visibility_threshold_px: m["visibility_threshold_px"].as_u64(),
        depth_encoding: depth["scale"]
            .as_f64()
            .map(|s| (s, depth["background"].as_u64().unwrap_or(65535) as u16)),
        size,
    })
}

/// The camera of a sample's metadata (ours only): `K`, world-to-camera `E` and its position.
fn camera_of(m: &Value) -> Option<Camera> {
    let c = &m["camera"];
    let num = |v: &Value| v.as_f64();
    let mut k = [[0.0; 3]; 3];
    let mut e = [[0.0; 4]; 4];
    for r in 0..3 {
        for col in 0..3 {
            k[r][col] = num(&c["intrinsics"][r][col])?;
        }
    }
    for (r, row) in e.iter_mut().enumerate() {
        for (col, v) in row.iter_mut().enumerate() {
            *v = num(&c["extrinsics"][r][col])?;
        }
    }
    let w = &c["matrix_world"];
    let location = [num(&w[0][3])?, num(&w[1][3])?, num(&w[2][3])?];
    Some(Camera { k, e, location })
}
