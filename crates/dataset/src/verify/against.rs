//! `clevrtex verify DIR --against OTHER`: do two datasets made by the same command (on other
//! machines, Blender versions, shard counts) hold the same layouts, masks and metadata, image
//! by image? Masks and metadata are byte-identical across machines and Blender versions but
//! for the metadata's provenance fields ([`crate::fingerprint::PROVENANCE_KEYS`]); the
//! rendered passes (RGB, depth, normals, albedo, shadow, kept EXRs) carry render noise, so
//! their differences are counted as such, not as failures.
//!
//! Each side is read by the one walk ([`Dataset::open`]) and its run manifests. Where a side's
//! files are present, every mask and metadata file is read and hashed as `verify` hashes
//! them, and checked against that side's own manifests: a file that differs from its
//! manifest, a file a manifest claims that is missing, a file no finished manifest claims is
//! a difference, as are a differing mask, metadata (compared as values, provenance left out:
//! `1.5` and `1.50` are the same) and layout fingerprint. A side of manifests only (OTHER may
//! be just its `MANIFEST-*.json` in `clevrtex_<variant>/` folders) is compared by its claims,
//! and the report says so ([`Comparison::claims_only`]). Runs made with other settings (seed,
//! config, render settings, passes, user materials, suite, `--total`) are named and their
//! images not compared.

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};

use serde::Serialize;

use crate::dataset::{self, Dataset};
use crate::fingerprint;
use crate::layout;
use crate::manifest::{Manifest, Xxh3};
use clevrtex_scene::Pass;
use rayon::prelude::*;

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
    /// a side of manifests only). Two that differ are a difference.
    pub fingerprints: [String; 2],
    /// Whether each side (this dataset's, the other's) was compared by its manifests' claims
    /// alone: no sample's files were found, so its files were not read and nothing about them
    /// is proven.
    pub claims_only: [bool; 2],
}

impl Comparison {
    /// Whether the two datasets hold the same layouts, masks and metadata at every index.
    pub fn same(&self) -> bool {
        self.settings.is_empty()
            && self.differ_count == 0
            && self.only_here.is_empty()
            && self.only_there.is_empty()
            && self.compared > 0
            && (self.fingerprints[0].is_empty()
                || self.fingerprints[1].is_empty()
                || self.fingerprints[0] == self.fingerprints[1])
    }
}

/// One file of one sample on one side: what its finished manifest claims and, where the
/// side's files are present, what is on disk. Small (24 bytes) for a side of manifests only:
/// a manifest of a million files costs about its own size again.
#[derive(Debug, Clone, Default)]
struct SideFile {
    /// The xxh3 a finished manifest of the side records for it.
    claimed: Option<Xxh3>,
    /// The file as found on disk (a regular file of the sample's folder), if it was.
    disk: Option<Box<DiskFile>>,
}

/// A file found on disk.
#[derive(Debug, Clone)]
struct DiskFile {
    /// Mask and metadata only: the xxh3 of its bytes as read, or why they were not read.
    read: Option<Result<Xxh3, String>>,
    /// Its path, and the dataset root it is read beneath.
    path: PathBuf,
    root: PathBuf,
}

/// One sample's files on one side: (file name, what is known of it), sorted by name.
#[derive(Debug, Default)]
struct SampleFiles(Vec<(Box<str>, SideFile)>);

impl SampleFiles {
    fn get(&self, name: &str) -> Option<&SideFile> {
        let at = self.0.binary_search_by(|(n, _)| (**n).cmp(name)).ok()?;
        Some(&self.0[at].1)
    }

    fn contains_key(&self, name: &str) -> bool {
        self.get(name).is_some()
    }

    fn keys(&self) -> impl Iterator<Item = &str> {
        self.0.iter().map(|(n, _)| &**n)
    }

    fn iter(&self) -> impl Iterator<Item = (&str, &SideFile)> {
        self.0.iter().map(|(n, f)| (&**n, f))
    }

    /// The file `name`, added (unknown so far) where it is not listed yet.
    fn entry(&mut self, name: &str) -> &mut SideFile {
        let at = match self.0.binary_search_by(|(n, _)| (**n).cmp(name)) {
            Ok(at) => at,
            Err(at) => {
                self.0.insert(at, (name.into(), SideFile::default()));
                at
            }
        };
        &mut self.0[at].1
    }
}

/// A file found on disk: index, stem, name, path, and its hash as read (mask and metadata).
type OnDisk = (u64, String, String, PathBuf, Option<Result<Xxh3, String>>);

/// One side's files of a variant: (index, stem) -> file name -> what is known of it.
type Files = BTreeMap<(u64, String), SampleFiles>;

/// One side of a variant: its manifests (path, contents, dataset root), their files, and
/// whether any sample's files were found on disk (else it is compared by its manifests'
/// claims alone).
#[derive(Default)]
struct Side {
    manifests: Vec<(PathBuf, Manifest, PathBuf)>,
    files: Files,
    has_files: bool,
}

impl Side {
    /// The xxh3 this side holds for a file: what is on disk where the side's files are
    /// present (mask and metadata read; `None` when missing or unreadable), else its claim.
    fn hash(&self, f: &SideFile) -> Option<Xxh3> {
        if self.has_files {
            match f.disk.as_deref().map(|d| &d.read) {
                Some(Some(Ok(h))) => Some(*h),
                Some(Some(Err(_))) => None,
                Some(None) => f.claimed,
                None => None,
            }
        } else {
            f.claimed
        }
    }
}

/// Whether `name` is a file whose bytes `--against` compares (mask and metadata), as opposed
/// to a rendered pass (render noise).
fn compared_bytes(stem: &str, name: &str) -> bool {
    name == layout::metadata_file(stem) || name == layout::pass_file(stem, Pass::Mask)
}

fn sides(roots: &[PathBuf]) -> Result<BTreeMap<String, Side>, String> {
    let mut out: BTreeMap<String, Side> = BTreeMap::new();
    let mut seen = BTreeSet::new();
    let mut seen_dirs = BTreeSet::new();
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
                    for (rel, e) in &m.files {
                        let name = rel.rsplit('/').next().unwrap_or(rel);
                        if rel.contains("..") {
                            continue;
                        }
                        if let Some((stem, _, index)) = layout::parse_file_name(name) {
                            let f = side
                                .files
                                .entry((index, stem.to_string()))
                                .or_default()
                                .entry(name);
                            f.claimed = Some(e.xxh3);
                        }
                    }
                }
                side.manifests.push((p.clone(), m, ds.root.clone()));
            }
            // The files on disk, read by the one walk: every mask and metadata file read and
            // hashed as `verify` hashes them.
            if !seen_dirs.insert(dataset::root(&vd.dir).unwrap_or_else(|_| vd.dir.clone())) {
                continue;
            }
            let side = out.entry(vd.variant.clone()).or_default();
            let samples: Vec<&dataset::SampleRef> = vd
                .samples
                .iter()
                .filter(|s| s.variant == vd.variant)
                .collect();
            side.has_files |= !samples.is_empty();
            let read: Vec<OnDisk> = samples
                .par_iter()
                .flat_map_iter(|s| {
                    s.files.iter().map(|name| {
                        let path = s.path(name);
                        let read = compared_bytes(&s.stem, name).then(|| {
                            dataset::read(&ds.root, &path, dataset::MAX_FILE_BYTES)
                                .map(|b| Xxh3::of(&b))
                        });
                        (s.index, s.stem.clone(), name.clone(), path, read)
                    })
                })
                .collect();
            for (index, stem, name, path, read) in read {
                let f = side.files.entry((index, stem)).or_default().entry(&name);
                f.disk = Some(Box::new(DiskFile {
                    read,
                    path,
                    root: ds.root.clone(),
                }));
            }
        }
    }
    Ok(out)
}

/// What of one sample a side holds that its own manifests do not say (where its files are
/// present): a file claimed but missing, a mask or metadata file of other bytes than claimed
/// or unreadable, a file no finished manifest claims. `side` names it (`here`, `there`).
fn own_problems(side: &Side, files: &SampleFiles, who: &str) -> Vec<String> {
    if !side.has_files {
        return Vec::new();
    }
    let mut out = Vec::new();
    for (name, f) in files.iter() {
        let name = clevrtex_scene::text::printable(name);
        let read = f.disk.as_deref().and_then(|d| d.read.as_ref());
        match (&f.claimed, f.disk.is_some(), read) {
            (Some(_), false, _) => out.push(format!("`{name}` is in a manifest {who} but missing")),
            (_, true, Some(Err(why))) => out.push(format!("`{name}` {who} {why}")),
            (Some(c), true, Some(Ok(h))) if c != h => out.push(format!(
                "`{name}` {who} differs from its manifest (xxh3 {h}; manifest: {c})"
            )),
            (None, true, _) => out.push(format!("`{name}` {who} is in no finished manifest")),
            _ => {}
        }
    }
    out
}

/// The settings in which the two sides' runs differ.
fn settings(here: &Side, there: &Side) -> Vec<String> {
    let (Some((_, h, _)), Some((_, t, _))) = (here.manifests.first(), there.manifests.first())
    else {
        return Vec::new();
    };
    let mut d = super::run_differences(h, t);
    if h.total != t.total {
        d.push(format!("--total {} vs {}", h.total, t.total));
    }
    let show = |s: &Option<String>| s.clone().unwrap_or_else(|| "(none)".into());
    if h.suite != t.suite {
        d.push(format!("suite {} vs {}", show(&h.suite), show(&t.suite)));
    }
    d.into_iter()
        .map(|x| clevrtex_scene::text::printable(&x).into_owned())
        .collect()
}

/// Whether two JSON values are the same value: numbers compared as numbers (`1.5`, `1.50`
/// and `15e-1` are one value; `2` and `2.0` too), objects key by key, arrays item by item.
pub(crate) fn same_value(a: &serde_json::Value, b: &serde_json::Value) -> bool {
    use serde_json::Value as V;
    match (a, b) {
        (V::Number(x), V::Number(y)) => match (x.as_u64(), y.as_u64(), x.as_i64(), y.as_i64()) {
            (Some(p), Some(q), _, _) => p == q,
            (_, _, Some(p), Some(q)) => p == q,
            _ => x.as_f64() == y.as_f64(),
        },
        (V::Array(x), V::Array(y)) => {
            x.len() == y.len() && x.iter().zip(y).all(|(p, q)| same_value(p, q))
        }
        (V::Object(x), V::Object(y)) => {
            x.len() == y.len()
                && x.iter()
                    .all(|(k, v)| y.get(k).is_some_and(|w| same_value(v, w)))
        }
        _ => a == b,
    }
}

/// The top-level keys in which two metadata files differ as values, provenance left out;
/// `None` when one cannot be read (a side of manifests only).
fn metadata_keys(a: &SideFile, b: &SideFile) -> Option<Vec<String>> {
    let read = |f: &SideFile| {
        let d = f.disk.as_deref()?;
        dataset::read(&d.root, &d.path, dataset::MAX_METADATA_BYTES)
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
            .filter(|k| match (x.get(*k), y.get(*k)) {
                (Some(p), Some(q)) => !same_value(p, q),
                _ => true,
            })
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
        claims_only: [
            !here.has_files && !here.manifests.is_empty(),
            !there.has_files && !there.manifests.is_empty(),
        ],
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
    let name_one = |c: &mut Comparison, stem: &str, problems: Vec<String>| {
        c.differ_count += 1;
        if c.differ.len() < MAX_NAMED {
            c.differ.push(format!("{stem}: {}", problems.join("; ")));
        }
    };
    // What each side holds that its own manifests do not say, also of images only one side has.
    for (key, files) in &here.files {
        if !there.files.contains_key(key) {
            let p = own_problems(here, files, "here");
            if !p.is_empty() {
                name_one(&mut c, &key.1, p);
            }
        }
    }
    for (key, files) in &there.files {
        if !here.files.contains_key(key) {
            let p = own_problems(there, files, "there");
            if !p.is_empty() {
                name_one(&mut c, &key.1, p);
            }
        }
    }
    // The images both hold.
    for (key, h) in &here.files {
        let Some(t) = there.files.get(key) else {
            continue;
        };
        let stem = &key.1;
        c.compared += 1;
        let mut problems = own_problems(here, h, "here");
        problems.extend(own_problems(there, t, "there"));
        let names: BTreeSet<&str> = h.keys().chain(t.keys()).collect();
        for name in names {
            let (a, b) = (
                h.get(name).and_then(|f| here.hash(f).map(|x| (f, x))),
                t.get(name).and_then(|f| there.hash(f).map(|x| (f, x))),
            );
            let (Some((fa, a)), Some((fb, b))) = (a, b) else {
                let shown = clevrtex_scene::text::printable(name);
                match (h.contains_key(name), t.contains_key(name)) {
                    (true, false) => problems.push(format!("`{shown}` only here")),
                    (false, true) => problems.push(format!("`{shown}` only there")),
                    // Held by both sides' lists but missing or unreadable on one: named above.
                    _ => {}
                }
                continue;
            };
            if a == b {
                continue;
            }
            if *name == layout::metadata_file(stem) {
                match metadata_keys(fa, fb) {
                    Some(keys) if keys.is_empty() => {}
                    Some(keys) => problems.push(format!(
                        "metadata differs in {}",
                        keys.iter().take(10).cloned().collect::<Vec<_>>().join(", ")
                    )),
                    None => problems.push(format!(
                        "metadata bytes differ (xxh3 {a} vs {b}; a side of manifests only cannot tell a provenance field from the layout: compare with both datasets' files)"
                    )),
                }
            } else if *name == layout::pass_file(stem, Pass::Mask) {
                problems.push(format!("mask differs (xxh3 {a} vs {b})"));
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
            name_one(&mut c, stem, problems);
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
