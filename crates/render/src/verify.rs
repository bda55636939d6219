//! `clevrtex verify`: is a dataset (one output folder, or the union of several shards' folders)
//! complete and intact?
//!
//! Per variant: every index of the run present exactly once (the run's indices come from the
//! manifests, else from `0..=max` of what is there), every sample's metadata readable and
//! naming files that exist, every requested pass a PNG of the right size and layout, mask ids
//! exactly `0..=N` with every object above the visibility threshold (recounted, and equal to
//! the metadata), no temporary files, every file's bytes equal to its manifest entry, and the
//! failure ledger summarised.

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};

use clevrtex_scene::layout;
use clevrtex_scene::passes::PngKind;
use clevrtex_scene::Pass;
use rayon::prelude::*;
use serde::Serialize;
use serde_json::Value;

use crate::manifest::{self, FileEntry, Manifest};
use crate::output::TMP_SUFFIX;

/// One sample found on disk: its files by name, and the folder they are in.
#[derive(Debug, Clone)]
struct Found {
    /// Variant folder the sample is under (`.../clevrtex_<variant>`).
    variant_dir: PathBuf,
    /// The sample's folder.
    dir: PathBuf,
    /// File names in `dir` that belong to the stem.
    files: BTreeSet<String>,
}

/// A broken sample and why.
#[derive(Debug, Clone, Serialize)]
pub struct Broken {
    /// Image index.
    pub index: u64,
    /// File stem.
    pub stem: String,
    /// The sample's folder.
    pub dir: PathBuf,
    /// What is wrong, one line each.
    pub problems: Vec<String>,
}

/// What `verify` found for one variant.
#[derive(Debug, Clone, Default, Serialize)]
pub struct VariantReport {
    /// Variant name.
    pub variant: String,
    /// Indices the run was to make (from the manifests, else `0..=max found`).
    pub expected: u64,
    /// Where the expected indices came from.
    pub expected_from: String,
    /// Complete, intact samples.
    pub ok: u64,
    /// Expected indices with no sample.
    pub missing: Vec<u64>,
    /// Indices found more than once, with every folder they are in.
    pub duplicates: BTreeMap<u64, Vec<PathBuf>>,
    /// Samples found but broken.
    pub broken: Vec<Broken>,
    /// Samples whose index the run did not ask for.
    pub unexpected: Vec<u64>,
    /// Temporary files left by killed runs.
    pub temp_files: Vec<PathBuf>,
    /// Manifests read.
    pub manifests: Vec<PathBuf>,
    /// Problems with the manifests themselves (unreadable, shards that disagree or lack one).
    pub manifest_problems: Vec<String>,
    /// Entries of the failure ledgers: index -> error.
    pub ledger: BTreeMap<u64, String>,
    /// Commands that made the run (from the manifests), to rerun after repair.
    pub commands: Vec<Vec<String>>,
}

impl VariantReport {
    /// Whether the variant is whole: every expected index once, intact, no temporary files,
    /// no manifest problems.
    pub fn is_whole(&self) -> bool {
        self.missing.is_empty()
            && self.duplicates.is_empty()
            && self.broken.is_empty()
            && self.temp_files.is_empty()
            && self.manifest_problems.is_empty()
    }
}

/// Options of a verification.
#[derive(Debug, Clone, Default)]
pub struct VerifyOptions {
    /// Only this variant.
    pub variant: Option<String>,
}

/// Manifest entries by (variant folder, stem): file name -> entry.
type Entries = BTreeMap<(PathBuf, String), BTreeMap<String, FileEntry>>;

/// Every `clevrtex_<variant>` folder under `roots` (a root may itself be one).
fn variant_dirs(roots: &[PathBuf]) -> BTreeMap<String, Vec<PathBuf>> {
    let mut out: BTreeMap<String, Vec<PathBuf>> = BTreeMap::new();
    for root in roots {
        let name = root
            .file_name()
            .map(|n| n.to_string_lossy().into_owned())
            .unwrap_or_default();
        if let Some(v) = name.strip_prefix("clevrtex_") {
            out.entry(v.to_string()).or_default().push(root.clone());
            continue;
        }
        if let Ok(entries) = std::fs::read_dir(root) {
            let mut dirs: Vec<PathBuf> = entries.flatten().map(|e| e.path()).collect();
            dirs.sort();
            for d in dirs.into_iter().filter(|d| d.is_dir()) {
                let name = d.file_name().unwrap().to_string_lossy().into_owned();
                if let Some(v) = name.strip_prefix("clevrtex_") {
                    out.entry(v.to_string()).or_default().push(d);
                }
            }
        }
    }
    out
}

/// Verify the dataset under `roots`. Errors only for unreadable roots.
pub fn verify(roots: &[PathBuf], opts: &VerifyOptions) -> Result<Vec<VariantReport>, String> {
    for r in roots {
        if !r.is_dir() {
            return Err(format!("`{}` is not a folder", r.display()));
        }
    }
    let mut reports = Vec::new();
    for (variant, dirs) in variant_dirs(roots) {
        if opts.variant.as_ref().is_some_and(|v| *v != variant) {
            continue;
        }
        reports.push(verify_variant(&variant, &dirs));
    }
    Ok(reports)
}

fn verify_variant(variant: &str, dirs: &[PathBuf]) -> VariantReport {
    let mut rep = VariantReport {
        variant: variant.to_string(),
        ..VariantReport::default()
    };
    // Samples by index, every place they are found.
    let mut found: BTreeMap<u64, Vec<(String, Found)>> = BTreeMap::new();
    let mut manifests = Vec::new();
    for vdir in dirs {
        let Ok(entries) = std::fs::read_dir(vdir) else {
            continue;
        };
        let mut entries: Vec<PathBuf> = entries.flatten().map(|e| e.path()).collect();
        entries.sort();
        for p in entries {
            let name = p.file_name().unwrap().to_string_lossy().into_owned();
            if p.is_dir() {
                scan_sample_dir(vdir, &p, &mut found, &mut rep.temp_files);
            } else if name.starts_with("MANIFEST-") && name.ends_with(".json") {
                match Manifest::read(&p) {
                    Ok(m) => manifests.push((p.clone(), m)),
                    Err(e) => rep
                        .manifest_problems
                        .push(format!("`{}` cannot be read: {e}", p.display())),
                }
                rep.manifests.push(p);
            } else if name == "failures.jsonl" {
                read_ledger(&p, &mut rep.ledger);
            } else if name.ends_with(TMP_SUFFIX) {
                rep.temp_files.push(p);
            }
        }
    }

    // The expected indices, and the manifest entry of each file.
    let mut expected: BTreeSet<u64> = BTreeSet::new();
    // Manifest entries by (variant folder, stem): file name -> entry.
    let mut entries: Entries = BTreeMap::new();
    if manifests.is_empty() {
        if let Some((&max, _)) = found.last_key_value() {
            expected.extend(0..=max);
        }
        rep.expected_from = "no manifest: indices 0 to the largest found".into();
    } else {
        let first = &manifests[0].1;
        let (start, end, n) = (first.start, first.end, first.shard[1]);
        let mut shards = BTreeSet::new();
        for (path, m) in &manifests {
            if (m.start, m.end, m.shard[1], m.seed, &m.config_hash)
                != (start, end, n, first.seed, &first.config_hash)
            {
                rep.manifest_problems.push(format!(
                    "`{}` is from another run (indices {}..{}, {} shards, seed {}) than `{}` ({start}..{end}, {n} shards, seed {})",
                    path.display(), m.start, m.end, m.shard[1], m.seed, manifests[0].0.display(), first.seed
                ));
            }
            shards.insert(m.shard[0]);
            expected.extend(m.indices());
            let vdir = path.parent().unwrap_or(Path::new(".")).to_path_buf();
            for (rel, e) in &m.files {
                let name = rel.rsplit('/').next().unwrap_or(rel);
                if let Some((stem, _)) = stem_of(name) {
                    entries
                        .entry((vdir.clone(), stem.to_string()))
                        .or_default()
                        .insert(name.to_string(), e.clone());
                }
            }
            if !rep.commands.contains(&m.command) {
                rep.commands.push(m.command.clone());
            }
        }
        let absent: Vec<String> = (0..n)
            .filter(|k| !shards.contains(k))
            .map(|k| format!("{k}/{n}"))
            .collect();
        if !absent.is_empty() {
            rep.manifest_problems.push(format!(
                "no manifest for shard(s) {} of the run: they did not finish (or their folders were not given)",
                absent.join(", ")
            ));
            // Their indices are still part of the run.
            expected.extend(start..end);
        }
        rep.expected_from = format!(
            "{} manifest(s): indices {start}..{end} in {n} shard(s), seed {}",
            manifests.len(),
            first.seed
        );
    }
    rep.expected = expected.len() as u64;
    rep.missing = expected
        .iter()
        .filter(|i| !found.contains_key(i))
        .copied()
        .collect();
    rep.unexpected = found
        .keys()
        .filter(|i| !expected.contains(i))
        .copied()
        .collect();
    let mut singles = Vec::new();
    for (index, places) in &found {
        if places.len() > 1 {
            rep.duplicates
                .insert(*index, places.iter().map(|(_, f)| f.dir.clone()).collect());
        } else {
            singles.push((*index, places[0].clone()));
        }
    }
    let checked: Vec<Result<(), Broken>> = singles
        .par_iter()
        .map(|(index, (stem, f))| check_sample(*index, stem, f, &entries))
        .collect();
    for c in checked {
        match c {
            Ok(()) => rep.ok += 1,
            Err(b) => rep.broken.push(b),
        }
    }
    rep
}

/// Collect the samples and temporary files of one `<index / 1000>` folder.
fn scan_sample_dir(
    vdir: &Path,
    dir: &Path,
    found: &mut BTreeMap<u64, Vec<(String, Found)>>,
    temps: &mut Vec<PathBuf>,
) {
    let Ok(entries) = std::fs::read_dir(dir) else {
        return;
    };
    let mut by_stem: BTreeMap<String, (u64, BTreeSet<String>)> = BTreeMap::new();
    let mut names: Vec<String> = entries
        .flatten()
        .map(|e| e.file_name().to_string_lossy().into_owned())
        .collect();
    names.sort();
    for name in names {
        if name.ends_with(TMP_SUFFIX) || (name.starts_with('.') && name.contains(".tmp")) {
            temps.push(dir.join(&name));
            continue;
        }
        let stem = stem_of(&name);
        if let Some((stem, index)) = stem {
            by_stem
                .entry(stem.to_string())
                .or_insert((index, BTreeSet::new()))
                .1
                .insert(name.clone());
        }
    }
    for (stem, (index, files)) in by_stem {
        found.entry(index).or_default().push((
            stem,
            Found {
                variant_dir: vdir.to_path_buf(),
                dir: dir.to_path_buf(),
                files,
            },
        ));
    }
}

/// The stem and index of a file of the layout (a pass, the metadata or a kept EXR).
fn stem_of(name: &str) -> Option<(&str, u64)> {
    let mut suffixes: Vec<String> = Pass::ALL
        .iter()
        .map(|&p| layout::pass_file("", p))
        .collect();
    suffixes.push(layout::metadata_file(""));
    suffixes.extend(layout::exr_files("", true));
    suffixes.sort_by_key(|s| std::cmp::Reverse(s.len()));
    suffixes
        .iter()
        .find_map(|s| layout::parse_stem(name, s))
        .map(|(stem, _, index)| (stem, index))
}

fn read_ledger(path: &Path, out: &mut BTreeMap<u64, String>) {
    if let Ok(text) = std::fs::read_to_string(path) {
        for line in text.lines() {
            if let Ok(v) = serde_json::from_str::<Value>(line) {
                if let Some(i) = v["index"].as_u64() {
                    let err = v["error"]
                        .as_str()
                        .unwrap_or("")
                        .lines()
                        .next()
                        .unwrap_or("");
                    out.insert(i, err.to_string());
                }
            }
        }
    }
}

/// The (bits, channels, palette) of a PNG kind.
fn png_layout(kind: PngKind) -> (u8, usize, bool) {
    match kind {
        PngKind::Palette8 => (8, 1, true),
        PngKind::Gray8 => (8, 1, false),
        PngKind::Rgb8 => (8, 3, false),
        PngKind::Gray16 => (16, 1, false),
        PngKind::Rgb16 => (16, 3, false),
    }
}

/// Check one sample; `Err` lists every problem found.
fn check_sample(index: u64, stem: &str, f: &Found, entries: &Entries) -> Result<(), Broken> {
    let mut problems = Vec::new();
    let variant_from_stem = layout::parse_stem(&format!("{stem}.json"), ".json")
        .map(|(_, v, _)| v.to_string())
        .unwrap_or_default();
    let want_dir = layout::sample_dir(
        f.variant_dir.parent().unwrap_or(Path::new("")),
        &variant_from_stem,
        index,
    );
    if want_dir != f.dir {
        problems.push(format!(
            "is in `{}`, not `{}`",
            f.dir.display(),
            want_dir.display()
        ));
    }
    let meta_name = layout::metadata_file(stem);
    let listed = entries.get(&(f.variant_dir.clone(), stem.to_string()));
    let mut bytes_of: BTreeMap<String, Vec<u8>> = BTreeMap::new();
    for name in &f.files {
        match std::fs::read(f.dir.join(name)) {
            Ok(b) => {
                match listed.and_then(|l| l.get(name)) {
                    Some(e) if e.size != b.len() as u64 || e.xxh3 != manifest::hash_hex(&b) => {
                        problems.push(format!(
                            "`{name}` differs from the manifest ({} bytes, xxh3 {}; manifest: {} bytes, xxh3 {})",
                            b.len(),
                            manifest::hash_hex(&b),
                            e.size,
                            e.xxh3
                        ))
                    }
                    None if !entries.is_empty() => {
                        problems.push(format!("`{name}` is not in any manifest"))
                    }
                    _ => {}
                }
                bytes_of.insert(name.clone(), b);
            }
            Err(e) => problems.push(format!("`{name}` cannot be read: {e}")),
        }
    }
    for name in listed.into_iter().flat_map(|l| l.keys()) {
        if !f.files.contains(name) {
            problems.push(format!("`{name}` is in the manifest but missing"));
        }
    }
    let Some(meta_bytes) = bytes_of.get(&meta_name) else {
        problems.push(format!("no metadata `{meta_name}` (an unfinished sample)"));
        return Err(broken(index, stem, f, problems));
    };
    let meta: Value = match serde_json::from_slice(meta_bytes) {
        Ok(v) => v,
        Err(e) => {
            problems.push(format!("metadata `{meta_name}` does not parse: {e}"));
            return Err(broken(index, stem, f, problems));
        }
    };
    let (w, h) = (
        meta["render"]["width"].as_u64().unwrap_or(0) as u32,
        meta["render"]["height"].as_u64().unwrap_or(0) as u32,
    );
    let n = meta["num_objects"].as_u64().unwrap_or(0) as usize;
    let threshold = meta["visibility_threshold_px"].as_u64().unwrap_or(0);
    if meta["image_index"].as_u64() != Some(index) {
        problems.push(format!(
            "metadata `image_index` is {} (the file name says {index})",
            meta["image_index"]
        ));
    }
    let passes: Vec<Pass> = meta["passes"]
        .as_object()
        .map(|m| m.keys().filter_map(|k| Pass::from_name(k)).collect())
        .unwrap_or_default();
    if passes.is_empty() {
        problems.push("metadata lists no `passes`".into());
    }
    for pass in passes {
        let name = layout::pass_file(stem, pass);
        let key = match pass {
            Pass::Rgb => "image_filename".to_string(),
            p => format!("{}_filename", p.name()),
        };
        if meta[&key].as_str() != Some(name.as_str()) {
            problems.push(format!(
                "metadata `{key}` is {} (expected \"{name}\")",
                meta[&key]
            ));
        }
        let Some(bytes) = bytes_of.get(&name) else {
            problems.push(format!("`{name}` is missing"));
            continue;
        };
        let png = match crate::post::decode_png_bytes(bytes, &f.dir.join(&name)) {
            Ok(p) => p,
            Err(crate::RenderError::BadOutput { problem, .. }) => {
                problems.push(format!("`{name}`: {problem}"));
                continue;
            }
            Err(e) => {
                problems.push(format!(
                    "`{name}`: {}",
                    e.to_string().lines().next().unwrap_or("")
                ));
                continue;
            }
        };
        if (png.width, png.height) != (w, h) {
            problems.push(format!(
                "`{name}` is {}x{} (the metadata says {w}x{h})",
                png.width, png.height
            ));
            continue;
        }
        let (bits, channels, palette) = png_layout(pass.spec().png);
        if (png.bits, png.channels, png.palette) != (bits, channels, palette) {
            problems.push(format!(
                "`{name}` is a {}-bit {}-channel{} PNG, expected {bits}-bit {channels}-channel{}",
                png.bits,
                png.channels,
                if png.palette { " palette" } else { "" },
                if palette { " palette" } else { "" }
            ));
            continue;
        }
        if pass == Pass::Mask {
            let mut counts = vec![0u64; 256];
            for &v in &png.data {
                counts[(v as usize).min(255)] += 1;
            }
            if let Some(bad) = (n + 1..256).find(|&i| counts[i] > 0) {
                problems.push(format!(
                    "mask has id {bad} but the metadata has {n} objects"
                ));
            }
            for i in 1..=n.min(255) {
                let listed = meta["objects"][i - 1]["visible_pixels"].as_u64();
                if counts[i] <= threshold {
                    problems.push(format!(
                        "object {i} has {} visible pixels, at or under the threshold {threshold}",
                        counts[i]
                    ));
                } else if listed.is_some_and(|l| l != counts[i]) {
                    problems.push(format!(
                        "object {i} has {} pixels in the mask but {} in the metadata",
                        counts[i],
                        listed.unwrap_or(0)
                    ));
                }
            }
        }
    }
    if problems.is_empty() {
        Ok(())
    } else {
        Err(broken(index, stem, f, problems))
    }
}

fn broken(index: u64, stem: &str, f: &Found, problems: Vec<String>) -> Broken {
    Broken {
        index,
        stem: stem.to_string(),
        dir: f.dir.clone(),
        problems,
    }
}

/// Remove every file of each broken sample (metadata first, so an interrupted removal still
/// leaves the sample incomplete) and the temporary files, so that rerunning the run's
/// `generate` command remakes exactly them. Returns the number of files removed.
pub fn remove_broken(report: &VariantReport) -> std::io::Result<usize> {
    let mut removed = 0;
    for b in &report.broken {
        let meta = b.dir.join(layout::metadata_file(&b.stem));
        if meta.exists() {
            std::fs::remove_file(&meta)?;
            removed += 1;
        }
        if let Ok(entries) = std::fs::read_dir(&b.dir) {
            for e in entries.flatten() {
                let name = e.file_name().to_string_lossy().into_owned();
                let of_stem = name
                    .strip_prefix(b.stem.as_str())
                    .is_some_and(|rest| rest.starts_with('_') || rest.starts_with('.'));
                if of_stem {
                    std::fs::remove_file(e.path())?;
                    removed += 1;
                }
            }
        }
    }
    for t in &report.temp_files {
        if std::fs::remove_file(t).is_ok() {
            removed += 1;
        }
    }
    Ok(removed)
}
