//! `clevrtex verify DIR --against OTHER`: do two datasets made by the same command (on other
//! machines, Blender versions, shard counts) hold the same layouts, masks and metadata, image
//! by image? Masks and metadata are byte-identical across machines and Blender versions but
//! for the metadata's provenance fields ([`crate::fingerprint::PROVENANCE_KEYS`]); the
//! rendered passes (RGB, depth, normals, albedo, shadow, kept EXRs) carry render noise, so
//! their differences are counted as such, not as failures.
//!
//! Each side is read from its run manifests (the file hashes of their finished runs): OTHER
//! may be just its manifests (`MANIFEST-*.json` in `clevrtex_<variant>/` folders). Where a
//! metadata file's bytes differ and both sides have the file, the two are compared without
//! their provenance fields, naming the keys that differ. Runs made with other settings (seed,
//! config, render settings, passes, user materials, suite, `--total`) are named and their
//! images not compared.

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};

use serde::Serialize;

use crate::dataset::{self, Dataset};
use crate::fingerprint;
use crate::layout;
use crate::manifest::Manifest;
use clevrtex_scene::Pass;

/// The most differing images named one by one (all are counted).
const MAX_NAMED: usize = 50;

/// What `--against` found for one variant.
#[derive(Debug, Clone, Default, Serialize)]
pub struct Comparison {
    /// Variant name.
    pub variant: String,
    /// The other dataset's folder.
    pub other: PathBuf,
    /// Settings in which the two datasets' runs differ (then no image is compared), one
    /// phrase each, this dataset's value first.
    pub settings: Vec<String>,
    /// Images in both datasets' finished runs, compared.
    pub compared: u64,
    /// Images whose layout (metadata without provenance) and mask are identical.
    pub identical: u64,
    /// Images whose rendered passes differ (render noise, not a failure), by pass.
    pub render_noise: BTreeMap<String, u64>,
    /// Images whose layout, mask or metadata differ: the first [`MAX_NAMED`], one line each.
    pub differ: Vec<String>,
    /// How many images differ.
    pub differ_count: u64,
    /// Indices only this dataset's finished runs hold.
    pub only_here: Vec<u64>,
    /// Indices only the other dataset's finished runs hold.
    pub only_there: Vec<u64>,
    /// The layout fingerprints of the two sides (empty where the metadata cannot be read:
    /// a side of manifests only).
    pub fingerprints: [String; 2],
}

impl Comparison {
    /// Whether the two datasets hold the same layouts, masks and metadata at every index.
    pub fn same(&self) -> bool {
        self.settings.is_empty()
            && self.differ_count == 0
            && self.only_here.is_empty()
            && self.only_there.is_empty()
            && self.compared > 0
    }
}

/// One side's finished files of a variant: stem -> file name -> (xxh3, path, dataset root).
type Files = BTreeMap<(u64, String), BTreeMap<String, (String, PathBuf, PathBuf)>>;

/// One side of a variant: its manifests (path, contents, dataset root) and their files.
#[derive(Default)]
struct Side {
    manifests: Vec<(PathBuf, Manifest, PathBuf)>,
    files: Files,
}

fn sides(roots: &[PathBuf]) -> Result<BTreeMap<String, Side>, String> {
    let mut out: BTreeMap<String, Side> = BTreeMap::new();
    let mut seen = BTreeSet::new();
    for r in roots {
        if !r.is_dir() {
            return Err(format!("`{}` is not a folder", r.display()));
        }
        let ds = Dataset::open(r).map_err(|e| e.to_string())?;
        for vd in &ds.variants {
            for p in &vd.manifests {
                if !seen.insert(dataset::root(p).unwrap_or_else(|_| p.clone())) {
                    continue;
                }
                let m = Manifest::read(p).map_err(|e| format!("`{}`: {e}", p.display()))?;
                let side = out.entry(vd.variant.clone()).or_default();
                if m.finished && m.variant == vd.variant {
                    let vdir = p.parent().unwrap_or(Path::new("."));
                    for (rel, e) in &m.files {
                        let name = rel.rsplit('/').next().unwrap_or(rel);
                        if rel.contains("..") {
                            continue;
                        }
                        if let Some((stem, _, index)) = layout::parse_file_name(name) {
                            side.files
                                .entry((index, stem.to_string()))
                                .or_default()
                                .insert(
                                    name.to_string(),
                                    (e.xxh3.clone(), vdir.join(rel), ds.root.clone()),
                                );
                        }
                    }
                }
                side.manifests.push((p.clone(), m, ds.root.clone()));
            }
        }
    }
    Ok(out)
}

/// The suite a manifest names (`generate --suite`), read from its JSON.
fn suite_of(root: &Path, path: &Path) -> Option<String> {
    let bytes = dataset::read(root, path, dataset::MAX_FILE_BYTES).ok()?;
    let v: serde_json::Value = serde_json::from_slice(&bytes).ok()?;
    v["suite"].as_str().map(str::to_string)
}

/// The settings in which the two sides' runs differ.
fn settings(here: &Side, there: &Side) -> Vec<String> {
    let (Some((hp, h, hr)), Some((tp, t, tr))) = (here.manifests.first(), there.manifests.first())
    else {
        return Vec::new();
    };
    let mut d = super::run_differences(h, t);
    if h.total != t.total {
        d.push(format!("--total {} vs {}", h.total, t.total));
    }
    let show = |s: Option<String>| s.unwrap_or_else(|| "(none)".into());
    let (hs, ts) = (suite_of(hr, hp), suite_of(tr, tp));
    if hs != ts {
        d.push(format!("suite {} vs {}", show(hs), show(ts)));
    }
    d.into_iter()
        .map(|x| clevrtex_scene::text::printable(&x).into_owned())
        .collect()
}

/// The top-level keys in which two metadata files differ, provenance left out; `None` when
/// one cannot be read (a side of manifests only).
fn metadata_keys(
    a: &(String, PathBuf, PathBuf),
    b: &(String, PathBuf, PathBuf),
) -> Option<Vec<String>> {
    let read = |(_, path, root): &(String, PathBuf, PathBuf)| {
        dataset::read(root, path, dataset::MAX_METADATA_BYTES)
            .ok()
            .and_then(|bytes| fingerprint::layout_of(&bytes))
    };
    let (x, y) = (read(a)?, read(b)?);
    let empty = serde_json::Map::new();
    let (x, y) = (
        x.as_object().unwrap_or(&empty),
        y.as_object().unwrap_or(&empty),
    );
    let keys: BTreeSet<&String> = x.keys().chain(y.keys()).collect();
    Some(
        keys.into_iter()
            .filter(|k| x.get(*k) != y.get(*k))
            .map(|k| clevrtex_scene::text::printable(k).into_owned())
            .collect(),
    )
}

/// Compare one variant's two sides image by image.
fn compare(variant: &str, other: &Path, here: &Side, there: &Side) -> Comparison {
    let mut c = Comparison {
        variant: variant.to_string(),
        other: other.to_path_buf(),
        settings: settings(here, there),
        ..Comparison::default()
    };
    let layouts = |s: &Side| {
        let mut by_dir: BTreeMap<(PathBuf, PathBuf), Vec<&Manifest>> = BTreeMap::new();
        for (p, m, root) in &s.manifests {
            let vdir = p.parent().unwrap_or(Path::new(".")).to_path_buf();
            by_dir.entry((root.clone(), vdir)).or_default().push(m);
        }
        // One folder: its fingerprint; shards in several folders: over all of them.
        if by_dir.len() == 1 {
            let ((root, vdir), ms) = by_dir.into_iter().next().expect("one");
            fingerprint::layouts(&root, &vdir, &ms).fingerprint
        } else {
            String::new()
        }
    };
    c.fingerprints = [layouts(here), layouts(there)];
    if !c.settings.is_empty() {
        return c;
    }
    for key in here.files.keys() {
        if !there.files.contains_key(key) {
            c.only_here.push(key.0);
        }
    }
    for key in there.files.keys() {
        if !here.files.contains_key(key) {
            c.only_there.push(key.0);
        }
    }
    // The images both hold.
    for (key, h) in &here.files {
        let Some(t) = there.files.get(key) else {
            continue;
        };
        let stem = &key.1;
        c.compared += 1;
        let mut problems = Vec::new();
        let names: BTreeSet<&String> = h.keys().chain(t.keys()).collect();
        for name in names {
            let (Some(a), Some(b)) = (h.get(name), t.get(name)) else {
                problems.push(format!(
                    "`{name}` only {}",
                    if h.contains_key(name) {
                        "here"
                    } else {
                        "there"
                    }
                ));
                continue;
            };
            if a.0 == b.0 {
                continue;
            }
            if *name == layout::metadata_file(stem) {
                match metadata_keys(a, b) {
                    Some(keys) if keys.is_empty() => {}
                    Some(keys) => problems.push(format!(
                        "metadata differs in {}",
                        keys.iter().take(10).cloned().collect::<Vec<_>>().join(", ")
                    )),
                    None => problems.push(format!(
                        "metadata bytes differ (xxh3 {} vs {}; a side of manifests only cannot tell a provenance field from the layout: compare with both datasets' files)",
                        a.0, b.0
                    )),
                }
            } else if *name == layout::pass_file(stem, Pass::Mask) {
                problems.push(format!("mask differs (xxh3 {} vs {})", a.0, b.0));
            } else {
                let pass = Pass::ALL
                    .iter()
                    .find(|p| *name == layout::pass_file(stem, **p))
                    .map_or("exr", |p| p.name());
                *c.render_noise.entry(pass.to_string()).or_insert(0) += 1;
            }
        }
        if problems.is_empty() {
            c.identical += 1;
        } else {
            c.differ_count += 1;
            if c.differ.len() < MAX_NAMED {
                c.differ.push(format!("{stem}: {}", problems.join("; ")));
            }
        }
    }
    c
}

/// Compare the dataset under `roots` with the one under `other`, variant by variant (only
/// `variant` if given). Errors for unreadable folders and manifests, and when the two share no
/// variant.
pub fn against(
    roots: &[PathBuf],
    other: &Path,
    variant: Option<&str>,
) -> Result<Vec<Comparison>, String> {
    let here = sides(roots)?;
    let there = sides(&[other.to_path_buf()])?;
    if there.is_empty() {
        return Err(format!(
            "`{}` holds no run manifest (`clevrtex_<variant>/MANIFEST-*.json`): nothing to compare against\nhint: pass the `--out` folder of another `clevrtex generate` run, or a copy of its manifests in their `clevrtex_<variant>` folders",
            other.display()
        ));
    }
    let names: BTreeSet<&String> = here.keys().chain(there.keys()).collect();
    let mut out = Vec::new();
    let empty = Side::default();
    for v in names {
        if variant.is_some_and(|w| w != v) {
            continue;
        }
        let (h, t) = (
            here.get(v).unwrap_or(&empty),
            there.get(v).unwrap_or(&empty),
        );
        let mut c = compare(v, other, h, t);
        if h.manifests.is_empty() || t.manifests.is_empty() {
            c.settings.push(format!(
                "variant `{}` only {}",
                clevrtex_scene::text::printable(v),
                if t.manifests.is_empty() {
                    "here"
                } else {
                    "in the other dataset"
                }
            ));
        }
        out.push(c);
    }
    Ok(out)
}
