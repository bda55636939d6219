//! `clevrtex verify`: is a dataset (one output folder, or the union of several shards' or runs'
//! folders) complete and intact?
//!
//! Per variant: every index of the runs present exactly once (the union of the manifests'
//! ranges, every run's plan included, else `0..=max` of what is there), every run finished,
//! every sample's metadata typed and naming the layout's files, every requested pass a PNG of
//! the right size and layout, mask ids exactly `0..=N` with every object above the visibility
//! threshold (recounted, and equal to the metadata), no temporary files, every file's bytes
//! equal to a manifest entry, and the failure ledger summarised. The dataset is walked and its
//! metadata typed by [`Dataset::open`] and [`MetadataView`] (no link out of the dataset, only
//! regular files, capped), and every count taken from a file is bounded before it sizes
//! anything ([`MAX_RUN_INDICES`]).

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};

use crate::layout;
use clevrtex_scene::scene_file::MAX_IMAGE_SIDE;
use clevrtex_scene::Pass;
use rayon::prelude::*;
use serde::Serialize;
use serde_json::Value;

use crate::dataset::{self, Dataset, MetadataView, VariantDir};
use crate::manifest::{in_ranges, merge_ranges as merge};

use crate::layout::TMP_SUFFIX;
use crate::manifest::{self, FileEntry, Manifest, MAX_RUN_INDICES};

/// One sample found on disk: its files by name, and the folder they are in.
#[derive(Debug, Clone)]
struct Found {
    /// The dataset root it was found under (canonical), which no link may leave.
    root: PathBuf,
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
    /// Whether a run of the manifests covers the index, so rerunning its command remakes the
    /// sample: only such samples are removed by `--remove-broken`.
    pub rerun_remakes: bool,
}

/// The most missing indices listed one by one (all are counted in `missing_count`).
pub const MAX_LISTED: usize = 1_000_000;

/// What `verify` found for one variant.
#[derive(Debug, Clone, Default, Serialize)]
pub struct VariantReport {
    /// Variant name.
    pub variant: String,
    /// Indices the run was to make (the union of the manifests' ranges, else `0..=max found`).
    pub expected: u64,
    /// Where the expected indices came from.
    pub expected_from: String,
    /// Complete, intact samples.
    pub ok: u64,
    /// Expected indices with no sample (the first [`MAX_LISTED`]).
    pub missing: Vec<u64>,
    /// How many expected indices have no sample.
    pub missing_count: u64,
    /// Indices found more than once, with each place (folder and stem: `0000001` and
    /// `000001` are both index 1).
    pub duplicates: BTreeMap<u64, Vec<PathBuf>>,
    /// Samples found but broken.
    pub broken: Vec<Broken>,
    /// Samples whose index the run did not ask for.
    pub unexpected: Vec<u64>,
    /// Temporary files left by killed runs.
    pub temp_files: Vec<PathBuf>,
    /// Entries not followed or not read: links leading out of the dataset, FIFOs, devices,
    /// files over the size cap (one line each, naming the path).
    pub skipped: Vec<String>,
    /// Manifests read.
    pub manifests: Vec<PathBuf>,
    /// Problems with the manifests themselves (unreadable, runs that did not finish, shards
    /// that disagree or lack one).
    pub manifest_problems: Vec<String>,
    /// Entries of the failure ledgers: index -> error.
    pub ledger: BTreeMap<u64, String>,
    /// Each split's samples (of those found once) as index ranges `[first, last]`, by the one
    /// split rule of every reader ([`dataset::splits`]: the recorded `split`, else by position).
    pub splits: BTreeMap<String, Vec<[u64; 2]>>,
    /// Commands to rerun after repair: those of the runs (from the manifests) whose indices
    /// are missing or broken or that did not finish, with `--out` set to the folder verified.
    pub commands: Vec<Vec<String>>,
    /// The user materials (`--materials DIR`) the runs drew from, by name, as their manifests
    /// record them (file, group, textures, content hash); two runs recording one name with
    /// different contents is a manifest problem. Left out of the JSON when empty.
    #[serde(skip_serializing_if = "BTreeMap::is_empty")]
    pub user_materials: BTreeMap<String, crate::manifest::UserMaterial>,
    /// The canonical roots of the datasets the variant was found in: what every delete of
    /// [`remove_broken`] is made relative to.
    #[serde(skip)]
    pub roots: Vec<PathBuf>,
}

impl VariantReport {
    /// Whether the variant is whole: every expected index once, intact, no temporary files,
    /// nothing skipped, no manifest problems (every planned run finished).
    pub fn is_whole(&self) -> bool {
        self.missing_count == 0
            && self.duplicates.is_empty()
            && self.broken.is_empty()
            && self.temp_files.is_empty()
            && self.skipped.is_empty()
            && self.manifest_problems.is_empty()
    }
}

/// Options of a verification.
#[derive(Debug, Clone, Default)]
pub struct VerifyOptions {
    /// Only this variant.
    pub variant: Option<String>,
}

/// A manifest read: its path, its contents and the folder its run's rerun writes into.
type ReadManifest = (PathBuf, Manifest, PathBuf);

/// Manifest entries by (variant folder, stem): file name -> the entries of every finished
/// manifest that lists it (a later run with `--overwrite` may have changed the bytes).
type Entries = BTreeMap<(PathBuf, String), BTreeMap<String, Vec<FileEntry>>>;

/// Variant folders by variant (each with the dataset it was found in), and what was not
/// followed by variant.
type VariantDirs<'a> = (
    BTreeMap<String, Vec<(&'a Dataset, &'a VariantDir)>>,
    BTreeMap<String, Vec<String>>,
);

/// Every `clevrtex_<variant>` folder of the datasets `opened` (a root may itself be one);
/// entries named like one but not followed go to the second map.
fn variant_dirs(opened: &[Dataset]) -> VariantDirs<'_> {
    let mut out: BTreeMap<String, Vec<(&Dataset, &VariantDir)>> = BTreeMap::new();
    let mut skipped: BTreeMap<String, Vec<String>> = BTreeMap::new();
    // A folder given twice (`verify D D`, `verify D D/clevrtex_full`, a link to it) is one
    // folder: counted once, not as duplicates of itself.
    let mut seen = BTreeSet::new();
    for ds in opened {
        for vd in &ds.variants {
            let canonical = crate::dataset::root(&vd.dir).unwrap_or_else(|_| vd.dir.clone());
            if seen.insert(canonical) {
                out.entry(vd.variant.clone()).or_default().push((ds, vd));
            }
        }
        for (v, skip) in &ds.skipped {
            skipped.entry(v.clone()).or_default().push(skip.to_string());
        }
    }
    (out, skipped)
}

/// Verify the dataset under `roots`. Errors only for unreadable roots.
pub fn verify(roots: &[PathBuf], opts: &VerifyOptions) -> Result<Vec<VariantReport>, String> {
    for r in roots {
        if !r.is_dir() {
            return Err(format!("`{}` is not a folder", r.display()));
        }
    }
    let opened = roots
        .iter()
        .map(|r| Dataset::open(r).map_err(|e| e.to_string()))
        .collect::<Result<Vec<_>, String>>()?;
    let (dirs, mut skipped) = variant_dirs(&opened);
    let mut names: BTreeSet<String> = dirs.keys().cloned().collect();
    names.extend(skipped.keys().cloned());
    let mut reports = Vec::new();
    for variant in names {
        if opts.variant.as_ref().is_some_and(|v| *v != variant) {
            continue;
        }
        let mut rep = verify_variant(&variant, dirs.get(&variant).map_or(&[], Vec::as_slice));
        rep.skipped
            .splice(0..0, skipped.remove(&variant).unwrap_or_default());
        reports.push(rep);
    }
    Ok(reports)
}

/// `command` with the value of its `--out` replaced by `out` (the folder that was verified,
/// wherever the run wrote it first).
fn with_out(command: &[String], out: &Path) -> Vec<String> {
    let out = out.display().to_string();
    let mut v = Vec::with_capacity(command.len());
    let mut it = command.iter();
    let mut replaced = false;
    while let Some(a) = it.next() {
        if a == "--out" {
            v.push(a.clone());
            if it.next().is_some() {
                v.push(out.clone());
                replaced = true;
            }
        } else if a.starts_with("--out=") {
            v.push(format!("--out={out}"));
            replaced = true;
        } else {
            v.push(a.clone());
        }
    }
    if !replaced {
        v.push("--out".into());
        v.push(out);
    }
    v
}

/// Flags of `clevrtex generate` a rerun command offered by `verify` may carry, with whether
/// each takes a value. None of them names a program (`--blender` is left out: the rerun
/// uses the user's own Blender); `--out` is set to the folder verified.
const RERUN_FLAGS: [(&str, bool); 24] = [
    ("--variant", true),
    ("--config", true),
    ("-n", true),
    ("--count", true),
    ("--seed", true),
    ("--start", true),
    ("--total", true),
    ("--shard", true),
    ("--shard-count", true),
    ("--width", true),
    ("--height", true),
    ("--samples", true),
    ("--shadow-samples", true),
    ("--quality", true),
    ("--max-attempts", true),
    ("--passes", true),
    ("--workers", true),
    ("--device", true),
    ("--threads", true),
    ("--timeout", true),
    ("--startup-timeout", true),
    ("--retries", true),
    ("--keep-exr", false),
    ("--out", true),
];

/// Whether a flag's value from a manifest may be offered: plain characters of numbers,
/// names, lists and paths, not empty, not a flag.
fn safe_value(v: &str) -> bool {
    !v.is_empty()
        && !v.starts_with('-')
        && v.chars()
            .all(|c| c.is_ascii_alphanumeric() || "._,/:+@%=-".contains(c))
}

/// The rerun command of a manifest's `command` (untrusted): `clevrtex generate` with only the
/// flags of [`RERUN_FLAGS`] whose values are [`safe_value`]s, `--out` set to `out`; `None`
/// when it is not a `generate` command.
fn rerun_command(command: &[String], out: &Path) -> Option<Vec<String>> {
    if command.get(1).map(String::as_str) != Some("generate") {
        return None;
    }
    let mut v = vec!["clevrtex".to_string(), "generate".to_string()];
    let mut it = command.iter().skip(2);
    while let Some(a) = it.next() {
        let (flag, inline) = match a.split_once('=') {
            Some((f, val)) if f.starts_with("--") => (f, Some(val)),
            _ => (a.as_str(), None),
        };
        let Some(&(_, takes)) = RERUN_FLAGS.iter().find(|(f, _)| *f == flag) else {
            continue;
        };
        if !takes {
            if inline.is_none() {
                v.push(flag.to_string());
            }
            continue;
        }
        let value = match inline {
            Some(val) => Some(val.to_string()),
            None => it.next().cloned(),
        };
        if let Some(val) = value.filter(|val| safe_value(val)) {
            v.push(flag.to_string());
            v.push(val);
        }
    }
    Some(with_out(&v, out))
}

/// `command` with `--shard k/n` (replacing its `--shard` and `--shard-count`).
fn with_shard(command: &[String], k: u64, n: u64) -> Vec<String> {
    let mut v = Vec::with_capacity(command.len() + 2);
    let mut it = command.iter();
    while let Some(a) = it.next() {
        if a == "--shard" || a == "--shard-count" {
            it.next();
        } else if !(a.starts_with("--shard=") || a.starts_with("--shard-count=")) {
            v.push(a.clone());
        }
    }
    v.push("--shard".into());
    v.push(format!("{k}/{n}"));
    v
}

fn verify_variant(variant: &str, dirs: &[(&Dataset, &VariantDir)]) -> VariantReport {
    let mut rep = VariantReport {
        variant: variant.to_string(),
        ..VariantReport::default()
    };
    // Samples by index, every place they are found.
    let mut found: BTreeMap<u64, Vec<(String, Found)>> = BTreeMap::new();
    // Manifests, with the folder their run's rerun writes into.
    let mut manifests: Vec<ReadManifest> = Vec::new();
    for (ds, vd) in dirs {
        if !rep.roots.contains(&ds.root) {
            rep.roots.push(ds.root.clone());
        }
        rep.skipped
            .extend(vd.skipped.iter().map(ToString::to_string));
        rep.skipped.extend(vd.misplaced.iter().map(|p| {
            format!(
                "`{}` is a sample's file outside its sample folder: not read as the dataset's, but the public loader's `**/` glob would read it as a sample (a second time when the sample is also in its folder); move or remove it",
                p.display()
            )
        }));
        rep.temp_files.extend(vd.temp_files.iter().cloned());
        for s in &vd.samples {
            found.entry(s.index).or_default().push((
                s.stem.clone(),
                Found {
                    root: ds.root.clone(),
                    variant_dir: vd.dir.clone(),
                    dir: s.dir.clone(),
                    files: s.files.clone(),
                },
            ));
        }
        for p in &vd.manifests {
            match Manifest::read(p) {
                Ok(m) => manifests.push((p.clone(), m, vd.out.clone())),
                Err(e) => rep
                    .manifest_problems
                    .push(format!("`{}` cannot be read: {e}", p.display())),
            }
            rep.manifests.push(p.clone());
        }
        for p in &vd.ledgers {
            read_ledger(ds, p, &mut rep.ledger, &mut rep.skipped);
        }
    }

    // The expected indices (the union of the runs' ranges), and the manifest entry of each
    // file. A run is the manifests of one range and shard count; its shards together make
    // `start..end`, and a shard without a manifest still belongs to the run.
    let mut entries: Entries = BTreeMap::new();
    let mut ranges = Vec::new();
    // Finished shards by run (start, end, n).
    let mut finished: BTreeMap<(u64, u64, u64), BTreeSet<u64>> = BTreeMap::new();
    if manifests.is_empty() && found.is_empty() && !dirs.is_empty() {
        // Nothing to check is not a whole dataset (a copy that lost its files).
        rep.manifest_problems.push(format!(
            "no sample and no run manifest in {}: nothing here was made by `clevrtex generate`, or its files were lost\nhint: check the folder given; a dataset has `<variant folder>/<bucket>/CLEVRTEX_<variant>_<index>.*` files",
            dirs.iter()
                .map(|(_, vd)| format!("`{}`", vd.dir.display()))
                .collect::<Vec<_>>()
                .join(", ")
        ));
    }
    if manifests.is_empty() {
        if let Some((&max, places)) = found.last_key_value() {
            if max >= MAX_RUN_INDICES {
                rep.manifest_problems.push(format!(
                    "no manifest, and the largest index found, {max} (`{}`), is over the {MAX_RUN_INDICES} indices a run may have: which indices the run made is unknown\nhint: remove files that are not the dataset's, or verify the folder of a run that wrote its manifest",
                    places[0].1.dir.join(&places[0].0).display()
                ));
            }
            ranges.push((0, max.saturating_add(1)));
        }
        rep.expected_from = "no manifest: indices 0 to the largest found".into();
    } else {
        let mut runs: BTreeMap<(u64, u64, u64), Vec<&ReadManifest>> = BTreeMap::new();
        for entry in &manifests {
            let m = &entry.1;
            for (name, um) in &m.user_materials {
                match rep.user_materials.get(name) {
                    Some(old) if old.xxh3 != um.xxh3 => rep.manifest_problems.push(format!(
                        "user material `{}` has content hash {} in `{}` and {} in another run: the runs drew from different files under one name",
                        clevrtex_scene::text::printable(name),
                        clevrtex_scene::text::printable(&um.xxh3),
                        entry.0.display(),
                        clevrtex_scene::text::printable(&old.xxh3)
                    )),
                    Some(_) => {}
                    None => {
                        rep.user_materials.insert(name.clone(), um.clone());
                    }
                }
            }
            runs.entry((m.start, m.end, m.shard[1]))
                .or_default()
                .push(entry);
        }
        for ((start, end, n), list) in &runs {
            let first = &list[0].1;
            let mut shards = BTreeSet::new();
            for (path, m, _) in list {
                if (m.seed, &m.config_hash) != (first.seed, &first.config_hash) {
                    rep.manifest_problems.push(format!(
                        "`{}` (seed {}) and `{}` (seed {}) are shards of indices {start}..{end} made with other seeds or configs",
                        path.display(), m.seed, list[0].0.display(), first.seed
                    ));
                }
                shards.insert(m.shard[0]);
                if !m.finished {
                    rep.manifest_problems.push(format!(
                        "`{}`: the run of indices {start}..{end} (shard {}/{n}) did not finish: it was interrupted, preempted or is still running (its plan was written, its end was not)",
                        path.display(),
                        m.shard[0]
                    ));
                    continue;
                }
                finished
                    .entry((*start, *end, *n))
                    .or_default()
                    .insert(m.shard[0]);
                let vdir = path.parent().unwrap_or(Path::new(".")).to_path_buf();
                for (rel, e) in &m.files {
                    let name = rel.rsplit('/').next().unwrap_or(rel);
                    if let Some((stem, _, _)) = layout::parse_file_name(name) {
                        entries
                            .entry((vdir.clone(), stem.to_string()))
                            .or_default()
                            .entry(name.to_string())
                            .or_default()
                            .push(e.clone());
                    }
                }
            }
            let absent: Vec<String> = (0..(*n).min(1000))
                .filter(|k| !shards.contains(k))
                .map(|k| format!("{k}/{n}"))
                .collect();
            if !absent.is_empty() {
                rep.manifest_problems.push(format!(
                    "no manifest for shard(s) {} of the run of indices {start}..{end}: they did not start (or their folders were not given)",
                    absent.join(", ")
                ));
            }
            ranges.push((*start, *end));
        }
        let n_runs = runs.len();
        rep.expected_from = if n_runs == 1 {
            let ((start, end, n), list) = runs.iter().next().expect("one run");
            format!(
                "{} manifest(s): indices {start}..{end} in {n} shard(s), seed {}",
                manifests.len(),
                list[0].1.seed
            )
        } else {
            let parts: Vec<String> = runs
                .keys()
                .map(|(s, e, n)| format!("{s}..{e} in {n} shard(s)"))
                .collect();
            format!(
                "{} manifest(s) of {n_runs} runs: indices {}",
                manifests.len(),
                parts.join(", ")
            )
        };
    }
    let ranges = merge(ranges);
    rep.expected = ranges.iter().map(|(a, b)| b - a).sum();
    if !manifests.is_empty() && rep.expected > MAX_RUN_INDICES {
        rep.manifest_problems.push(format!(
            "the manifests' runs hold {} indices, over the {MAX_RUN_INDICES} a dataset may have",
            rep.expected
        ));
    }
    // Missing: the gaps between the samples found, per range, counted without listing every
    // index (a range may be large).
    for &(a, b) in &ranges {
        let mut next = a;
        let keys = found.range(a..b).map(|(i, _)| *i).chain(std::iter::once(b));
        for i in keys {
            if i > next {
                rep.missing_count += i - next;
                let room = MAX_LISTED.saturating_sub(rep.missing.len()) as u64;
                rep.missing.extend(next..next + (i - next).min(room));
            }
            next = i.saturating_add(1);
        }
    }
    rep.unexpected = found
        .keys()
        .filter(|&&i| !in_ranges(&ranges, i))
        .copied()
        .collect();
    let covered_by_finished = |i: u64| {
        finished
            .iter()
            .any(|((s, e, n), ks)| (*s..*e).contains(&i) && ks.contains(&(i % n)))
    };
    let mut singles = Vec::new();
    for (index, places) in &found {
        if places.len() > 1 {
            rep.duplicates.insert(
                *index,
                places.iter().map(|(stem, f)| f.dir.join(stem)).collect(),
            );
        } else {
            singles.push((*index, places[0].clone(), covered_by_finished(*index)));
        }
    }
    // The split each run that covers an index gives it (the layout's position rule over the
    // run's `total`): what `generate` recorded, so what the sample's metadata must say.
    let splits_rule = layout::variant_splits(variant);
    let run_split = |index: u64| -> Vec<(layout::Split, String)> {
        manifests
            .iter()
            .filter(|(_, m, _)| m.covers(index))
            .map(|(p, m, _)| {
                (
                    layout::Split::of(splits_rule, index, m.total),
                    format!(
                        "the run of indices {}..{} of {} (`{}`)",
                        m.start,
                        m.end,
                        m.total,
                        p.file_name().unwrap_or_default().to_string_lossy()
                    ),
                )
            })
            .collect()
    };
    let checked: Vec<(Option<layout::Split>, Result<(), Broken>)> = singles
        .par_iter()
        .map(|(index, (stem, f), listed)| {
            // The manifests whose run claims the index: the sample must be what they say.
            let claims: Vec<&ReadManifest> = manifests
                .iter()
                .filter(|(_, m, _)| m.variant == variant && m.covers(*index))
                .collect();
            check_sample(
                *index,
                stem,
                f,
                &entries,
                *listed,
                &claims,
                &run_split(*index),
            )
        })
        .collect();
    let recorded: Vec<Option<layout::Split>> = checked.iter().map(|(s, _)| *s).collect();
    for ((index, _, _), split) in singles.iter().zip(dataset::splits(variant, &recorded)) {
        let ranges = rep.splits.entry(split.name().to_string()).or_default();
        match ranges.last_mut() {
            Some(r) if r[1] + 1 == *index => r[1] = *index,
            _ => ranges.push([*index, *index]),
        }
    }
    for (_, c) in checked {
        match c {
            Ok(()) => rep.ok += 1,
            Err(mut b) => {
                b.rerun_remakes = manifests.iter().any(|(_, m, _)| m.covers(b.index));
                rep.broken.push(b)
            }
        }
    }
    // The commands to rerun: those of runs with something to remake, `--out` the folder
    // verified (not where the run first wrote).
    // By range, not shard: the command of a shard whose sibling left no manifest is the
    // nearest one to adapt (`--shard`).
    // A run's command is offered when it remakes something: its own indices (its shard's)
    // missing or broken, or it did not finish. A shard that left no manifest (it never
    // started, or a range lock refused it) gets its sibling's command with its own `--shard`,
    // not the sibling's, which would remake nothing of it.
    let needs = |m: &Manifest| {
        !m.finished
            || rep.missing.iter().any(|&i| m.covers(i))
            || rep.broken.iter().any(|b| m.covers(b.index))
            || (rep.missing_count as usize > rep.missing.len()
                && rep.missing.iter().any(|&i| (m.start..m.end).contains(&i)))
    };
    let mut commands: Vec<Vec<String>> = Vec::new();
    let mut push = |c: Vec<String>| {
        if !commands.contains(&c) {
            commands.push(c);
        }
    };
    let mut shards_seen: BTreeMap<(u64, u64, u64), BTreeSet<u64>> = BTreeMap::new();
    for (_, m, _) in &manifests {
        shards_seen
            .entry((m.start, m.end, m.shard[1]))
            .or_default()
            .insert(m.shard[0]);
    }
    for (_, m, out) in &manifests {
        // Only a `clevrtex generate` command is offered, run as `clevrtex`, with only the
        // flags of a fixed list (a manifest is untrusted: its program name, `--blender` or
        // anything else that could name a program are never offered); others get the
        // plain hint.
        let Some(c) = rerun_command(&m.command, out) else {
            continue;
        };
        if needs(m) {
            push(c.clone());
        }
        let [_, n] = m.shard;
        if n > 1 {
            let seen = &shards_seen[&(m.start, m.end, n)];
            for k in (0..n.min(1000)).filter(|k| !seen.contains(k)).take(16) {
                let sibling = |i: u64| (m.start..m.end).contains(&i) && i % n == k;
                let remakes = rep.missing.iter().any(|&i| sibling(i))
                    || rep.broken.iter().any(|b| sibling(b.index))
                    || rep.missing_count as usize > rep.missing.len();
                if remakes {
                    push(with_shard(&c, k, n));
                }
            }
        }
    }
    rep.commands = commands;
    rep
}

/// The failure ledger's entries with an index: index -> the error's first line (500 characters).
fn read_ledger(
    ds: &Dataset,
    path: &Path,
    out: &mut BTreeMap<u64, String>,
    skipped: &mut Vec<String>,
) {
    let entries = match ds.read_ledger(path) {
        Ok(e) => e,
        Err(why) => {
            skipped.push(format!("`{}` {why}", path.display()));
            return;
        }
    };
    for e in entries {
        if let Some(i) = e.index {
            let err = e.error.lines().next().unwrap_or("");
            out.insert(i, err.chars().take(500).collect());
        }
    }
}

/// Check one sample; `Err` lists every problem found. `listed`: a finished manifest covers
/// the index, so every file must be in one.
/// Pixels of samples being decoded at once, over all threads: four samples of the largest size.
const PIXEL_BUDGET: u64 = 4 * (MAX_IMAGE_SIDE as u64) * (MAX_IMAGE_SIDE as u64);

/// A share of [`PIXEL_BUDGET`], held while a sample is decoded (waits while the budget is
/// spent; a sample larger than the whole budget waits for all of it).
struct PixelBudget(u64);

static BUDGET: (std::sync::Mutex<u64>, std::sync::Condvar) = (
    std::sync::Mutex::new(PIXEL_BUDGET),
    std::sync::Condvar::new(),
);

impl PixelBudget {
    fn take(pixels: u64) -> PixelBudget {
        let want = pixels.min(PIXEL_BUDGET);
        let (lock, freed) = &BUDGET;
        let mut left = lock.lock().unwrap_or_else(|e| e.into_inner());
        while *left < want {
            left = freed.wait(left).unwrap_or_else(|e| e.into_inner());
        }
        *left -= want;
        PixelBudget(want)
    }
}

impl Drop for PixelBudget {
    fn drop(&mut self) {
        let (lock, freed) = &BUDGET;
        *lock.lock().unwrap_or_else(|e| e.into_inner()) += self.0;
        freed.notify_all();
    }
}

/// Also the split the sample's metadata records (`None`: none, or not read). `runs`: the split
/// each run that covers the index gives it, with the run named.
fn check_sample(
    index: u64,
    stem: &str,
    f: &Found,
    entries: &Entries,
    listed_run: bool,
    claims: &[&ReadManifest],
    runs: &[(layout::Split, String)],
) -> (Option<layout::Split>, Result<(), Broken>) {
    let mut recorded = None;
    let result = check_sample_files(
        index,
        stem,
        f,
        entries,
        listed_run,
        claims,
        runs,
        &mut recorded,
    );
    (recorded, result)
}

#[allow(clippy::too_many_arguments)]
fn check_sample_files(
    index: u64,
    stem: &str,
    f: &Found,
    entries: &Entries,
    listed_run: bool,
    claims: &[&ReadManifest],
    runs: &[(layout::Split, String)],
    recorded: &mut Option<layout::Split>,
) -> Result<(), Broken> {
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
        match dataset::read(&f.root, &f.dir.join(name), dataset::MAX_FILE_BYTES) {
            Ok(b) => {
                match listed.and_then(|l| l.get(name)) {
                    Some(es)
                        if !es
                            .iter()
                            .any(|e| e.size == b.len() as u64 && e.xxh3 == manifest::hash_hex(&b)) =>
                    {
                        problems.push(format!(
                            "`{name}` differs from the manifest ({} bytes, xxh3 {}; manifest: {} bytes, xxh3 {})",
                            b.len(),
                            manifest::hash_hex(&b),
                            es[0].size,
                            es[0].xxh3
                        ))
                    }
                    None if listed_run => {
                        problems.push(format!("`{name}` is not in any manifest"))
                    }
                    _ => {}
                }
                bytes_of.insert(name.clone(), b);
            }
            Err(why) => problems.push(format!("`{name}` {why}")),
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
        Ok(v @ Value::Object(_)) => v,
        Ok(_) => {
            problems.push(format!("metadata `{meta_name}` is not a JSON object"));
            return Err(broken(index, stem, f, problems));
        }
        Err(e) => {
            problems.push(format!("metadata `{meta_name}` does not parse: {e}"));
            return Err(broken(index, stem, f, problems));
        }
    };
    // Every value that sizes or indexes something below, typed first.
    let view = match MetadataView::of(&meta, &meta_name) {
        Ok(v) => v,
        Err(e) => {
            problems.push(e.to_string());
            return Err(broken(index, stem, f, problems));
        }
    };
    let (w, h, n, threshold) = (
        view.width,
        view.height,
        view.num_objects,
        view.visibility_threshold_px,
    );
    let visible = &view.visible_pixels;
    // Decoding costs ~12 bytes a pixel over a sample's passes: however many threads check
    // samples, at most `PIXEL_BUDGET` pixels are decoded at once (about 0.8 GB), so that
    // samples declaring the largest size cannot add up to gigabytes on a many-core machine.
    let _budget = PixelBudget::take(u64::from(w) * u64::from(h));
    for (path, m, _) in claims {
        let differ = differs_from_manifest(&meta, &view, m);
        if !differ.is_empty() {
            problems.push(format!(
                "was not made by the run of the manifest `{}` that claims it (manifest vs metadata: {})",
                path.display(),
                differ.join(", ")
            ));
        }
    }
    // The recorded split (authoritative for every reader) must be the one the run that made
    // the sample gave it: the position rule over the run's `total`.
    match dataset::recorded_split(&meta["split"], &variant_from_stem, &meta_name) {
        Ok(Some(split)) => {
            *recorded = Some(split);
            if !runs.is_empty() && !runs.iter().any(|(s, _)| *s == split) {
                problems.push(format!(
                    "metadata `split` is `{}`, but {} puts index {index} in `{}`",
                    split.name(),
                    runs[0].1,
                    runs[0].0.name()
                ));
            }
        }
        Ok(None) => {}
        Err(e) => problems.push(e.to_string()),
    }
    if meta["image_index"].as_u64() != Some(index) {
        problems.push(format!(
            "metadata `image_index` is {} (the file name says {index})",
            dataset::short(&meta["image_index"])
        ));
    }
    // Kept EXRs (`--keep-exr`): checked without a manifest too (their bytes are the
    // manifest's business when there is one).
    for (name, bytes) in bytes_of.iter().filter(|(n, _)| n.ends_with(".exr")) {
        if let Err(why) = crate::exr::check_kept(bytes, (w as usize, h as usize)) {
            problems.push(format!("`{name}` {why}"));
        }
    }
    let passes = view.passes.clone();
    if passes.is_empty() {
        problems.push("metadata lists no `passes`".into());
    }
    for pass in passes {
        let name = layout::pass_file(stem, pass);
        let key = pass.metadata_key();
        if meta[key].as_str() != Some(name.as_str()) {
            problems.push(format!(
                "metadata `{key}` is {} (expected \"{name}\")",
                dataset::short(&meta[key])
            ));
        }
        let Some(bytes) = bytes_of.get(&name) else {
            problems.push(format!("`{name}` is missing"));
            continue;
        };
        // The header's size before decoding: a PNG claiming a huge size is never allocated.
        if let Some((pw, ph)) = crate::png::size(bytes) {
            if (pw, ph) != (w, h) {
                problems.push(format!("`{name}` is {pw}x{ph} (the metadata says {w}x{h})"));
                continue;
            }
        }
        // The mode from the header, by the readers' one rule: an RGB or 16-bit mask is named.
        if let Some(problem) = dataset::png_mode_problem(bytes, pass) {
            problems.push(format!("`{name}` {problem}"));
            continue;
        }
        let png = match crate::png::decode(bytes) {
            Ok(p) => p,
            Err(problem) => {
                problems.push(format!("`{name}`: {problem}"));
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
            for i in 1..=n {
                let listed = visible[i - 1];
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

/// What of a sample's metadata differs from the run settings of the manifest `m` that claims
/// it: variant, seed, config hash (when the metadata records one), passes, each render setting
/// (size, samples, ...), one phrase each.
fn differs_from_manifest(meta: &Value, view: &MetadataView, m: &Manifest) -> Vec<String> {
    let mut d = Vec::new();
    if meta["variant"].as_str() != Some(m.variant.as_str()) {
        d.push(format!(
            "variant {} vs {}",
            m.variant,
            dataset::short(&meta["variant"])
        ));
    }
    if meta["seed"].as_u64() != Some(m.seed) {
        d.push(format!(
            "seed {} vs {}",
            m.seed,
            dataset::short(&meta["seed"])
        ));
    }
    // Absent from older datasets (and `render`'s samples): not compared.
    if view
        .config_hash
        .as_ref()
        .is_some_and(|h| *h != m.config_hash)
    {
        d.push(format!(
            "config_hash {} vs {}",
            m.config_hash,
            dataset::short(&meta["config_hash"])
        ));
    }
    if !m.passes.is_empty() {
        let mut want: Vec<&str> = m.passes.iter().map(String::as_str).collect();
        let mut have: Vec<&str> = view.passes.iter().map(|p| p.name()).collect();
        want.sort_unstable();
        have.sort_unstable();
        if want != have {
            d.push(format!("passes {} vs {}", want.join(","), have.join(",")));
        }
    }
    if let Some(render) = &m.render {
        d.extend(manifest::render_differences(render, &meta["render"]));
    }
    d
}

fn broken(index: u64, stem: &str, f: &Found, problems: Vec<String>) -> Broken {
    Broken {
        index,
        stem: stem.to_string(),
        dir: f.dir.clone(),
        problems,
        rerun_remakes: false,
    }
}

/// What [`remove_broken`] did.
#[derive(Debug, Clone, Default)]
pub struct Removal {
    /// Files removed.
    pub files: usize,
    /// Broken samples kept because no run of the manifests covers them (no known command
    /// remakes them).
    pub kept: Vec<u64>,
}

/// Remove the files of each broken sample that a rerun of a manifest's run remakes
/// ([`Broken::rerun_remakes`]; metadata first, so an interrupted removal still leaves the
/// sample incomplete), and the temporary files of dead writers. Only names of the layout
/// (every pass, the metadata, the EXRs) are removed, in the sample's folder found inside the
/// dataset, and a link is removed as a link (its target is never touched). Each folder is
/// opened once relative to its dataset's root ([`dataset::open_dir_beneath`]) and every
/// delete is made relative to that handle (`unlinkat`): a folder swapped for a link leading
/// out of the dataset while this runs is refused, nothing outside is deleted. Duplicates are
/// only reported.
pub fn remove_broken(report: &VariantReport) -> std::io::Result<Removal> {
    remove_broken_with(report, &mut |_| {})
}

/// [`remove_broken`], calling `before_open` with each folder before it is opened (tests swap a
/// folder for a link there).
pub fn remove_broken_with(
    report: &VariantReport,
    before_open: &mut dyn FnMut(&Path),
) -> std::io::Result<Removal> {
    let mut out = Removal::default();
    let open = |dir: &Path| {
        dataset::open_dir_beneath(&report.roots, dir).map_err(|e| {
            if dataset::is_leads_out(&e) {
                std::io::Error::other(format!(
                    "`{}` leads out of the dataset through a symbolic link (swapped since it was checked?); nothing removed there\nhint: check what replaced that folder, then run `clevrtex verify --remove-broken` again",
                    dir.display()
                ))
            } else {
                e
            }
        })
    };
    for b in &report.broken {
        if !b.rerun_remakes {
            out.kept.push(b.index);
            continue;
        }
        let mut names = vec![layout::metadata_file(&b.stem)];
        names.extend(crate::layout::expected_files(&b.stem, &Pass::ALL, true));
        names.extend(layout::legacy_exr_files(&b.stem));
        names.dedup();
        before_open(&b.dir);
        let (_, handle) = open(&b.dir)?;
        for name in names {
            if dataset::remove_beneath(&handle, &name)? {
                out.files += 1;
            }
        }
    }
    for t in &report.temp_files {
        let name = t
            .file_name()
            .map(|n| n.to_string_lossy().into_owned())
            .unwrap_or_default();
        // A live writer's temporary (another shard writing now) is not stray.
        let live = name
            .strip_suffix(TMP_SUFFIX)
            .is_some_and(|stem| !crate::atomic::tagged_name_is_stale(stem));
        if live {
            continue;
        }
        let Some(dir) = t.parent() else { continue };
        before_open(dir);
        if let Ok((_, handle)) = open(dir) {
            if dataset::remove_beneath(&handle, &name).unwrap_or(false) {
                out.files += 1;
            }
        }
    }
    Ok(out)
}

/// Indices (sorted) as compact ranges for a message: `0, 3..=5, 9`; at most 20 ranges shown.
pub fn index_ranges(v: &[u64]) -> String {
    let mut out = Vec::new();
    let mut i = 0;
    while i < v.len() {
        let mut j = i;
        while j + 1 < v.len() && v[j + 1] == v[j] + 1 {
            j += 1;
        }
        out.push(if i == j {
            v[i].to_string()
        } else {
            format!("{}..={}", v[i], v[j])
        });
        i = j + 1;
    }
    let shown = out.len().min(20);
    let mut s = out[..shown].join(", ");
    if out.len() > shown {
        s += &format!(", ... ({} more ranges)", out.len() - shown);
    }
    s
}

/// A command line (a manifest's, untrusted) as a shell would read it back: control characters
/// escaped ([`clevrtex_scene::text::printable`]: no escape sequence reaches the terminal), each
/// word that is not plainly safe single-quoted, so a printed rerun command runs only that
/// command.
pub fn shell_words(args: &[String]) -> String {
    args.iter()
        .map(|a| clevrtex_scene::text::printable(a).into_owned())
        .map(|a| {
            if !a.is_empty()
                && a.chars()
                    .all(|c| c.is_ascii_alphanumeric() || "-_./=:,+@%".contains(c))
            {
                a.clone()
            } else {
                format!("'{}'", a.replace('\'', "'\\''"))
            }
        })
        .collect::<Vec<_>>()
        .join(" ")
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ranges_and_rerun_commands_print_safely() {
        assert_eq!(index_ranges(&[0, 3, 4, 5, 9]), "0, 3..=5, 9");
        let many: Vec<u64> = (0..50).map(|i| 2 * i).collect();
        assert!(index_ranges(&many).ends_with(", ... (30 more ranges)"));
        let cmd = ["clevrtex", "generate", "--out", "a b", "x;rm -rf ~", "it's"].map(String::from);
        assert_eq!(
            shell_words(&cmd),
            r"clevrtex generate --out 'a b' 'x;rm -rf ~' 'it'\''s'"
        );
        let hidden = ["\u{1b}[2K\rclevrtex".to_string()];
        assert_eq!(shell_words(&hidden), r"'\u{1b}[2K\u{d}clevrtex'");
    }

    /// A manifest's command is untrusted: the rerun offered keeps only flags of the fixed
    /// list with plain values (before, `--blender /tmp/evil.sh` was offered as it was).
    #[test]
    fn the_rerun_offers_no_program_from_a_manifest() {
        let c: Vec<String> = [
            "/tmp/evil",
            "generate",
            "--blender",
            "/tmp/evil.sh",
            "--seed",
            "3",
            "-n",
            "4",
            "--blender=/tmp/x.sh",
            "--config",
            "$(rm -rf ~)",
            "--keep-exr",
            "--out",
            "/old",
            "--shard",
            "0/2",
            "--exec",
            "sh",
        ]
        .map(String::from)
        .to_vec();
        let r = rerun_command(&c, Path::new("/new")).unwrap();
        assert_eq!(
            r,
            [
                "clevrtex",
                "generate",
                "--seed",
                "3",
                "-n",
                "4",
                "--keep-exr",
                "--out",
                "/new",
                "--shard",
                "0/2"
            ]
        );
        assert!(!shell_words(&r).contains("evil"));
        assert_eq!(
            with_shard(&r, 1, 2)[..],
            [
                "clevrtex",
                "generate",
                "--seed",
                "3",
                "-n",
                "4",
                "--keep-exr",
                "--out",
                "/new",
                "--shard",
                "1/2"
            ]
        );
        let other = ["clevrtex", "render", "x"].map(String::from).to_vec();
        assert!(rerun_command(&other, Path::new("/new")).is_none());
    }

    #[test]
    fn the_rerun_writes_where_verify_looked() {
        let c: Vec<String> = ["clevrtex", "generate", "--out", "/old", "-n", "4"]
            .map(String::from)
            .to_vec();
        assert_eq!(
            with_out(&c, Path::new("/new")),
            ["clevrtex", "generate", "--out", "/new", "-n", "4"]
        );
        let c: Vec<String> = ["clevrtex", "generate", "--out=/old"]
            .map(String::from)
            .to_vec();
        assert_eq!(
            with_out(&c, Path::new("/new")),
            ["clevrtex", "generate", "--out=/new"]
        );
    }

    /// `--remove-broken` deletes relative to a folder handle opened inside the dataset: a
    /// bucket swapped for a link to a canary folder while it runs (here between two samples)
    /// is refused, and nothing in the canary is deleted. Before, the canary's files of the
    /// layout's names were deleted.
    #[test]
    fn remove_broken_deletes_nothing_through_a_swapped_bucket() {
        let data = tempfile::tempdir().unwrap();
        let canary = tempfile::tempdir().unwrap();
        let root = dataset::root(data.path()).unwrap();
        let v = root.join("clevrtex_full");
        let mut broken = Vec::new();
        for index in [0u64, 1000] {
            let dir = layout::sample_dir(&root, "full", index);
            std::fs::create_dir_all(&dir).unwrap();
            let stem = layout::stem("full", index);
            for f in [
                layout::metadata_file(&stem),
                layout::pass_file(&stem, Pass::Rgb),
            ] {
                std::fs::write(dir.join(&f), b"x").unwrap();
                std::fs::write(canary.path().join(&f), b"canary").unwrap();
            }
            broken.push(Broken {
                index,
                stem,
                dir,
                problems: vec!["broken".into()],
                rerun_remakes: true,
            });
        }
        let report = VariantReport {
            variant: "full".into(),
            broken,
            roots: vec![root.clone()],
            ..VariantReport::default()
        };
        let second = v.join("1");
        let mut swap = |dir: &Path| {
            if dir == second {
                std::fs::rename(&second, v.join("moved")).unwrap();
                std::os::unix::fs::symlink(canary.path(), &second).unwrap();
            }
        };
        let got = remove_broken_with(&report, &mut swap);
        let e = got.unwrap_err().to_string();
        assert!(e.contains("leads out of the dataset"), "{e}");
        assert_eq!(
            std::fs::read_dir(canary.path()).unwrap().count(),
            4,
            "nothing in the canary is deleted"
        );
        assert_eq!(
            std::fs::read_dir(v.join("0")).unwrap().count(),
            0,
            "the first sample went"
        );
        assert_eq!(std::fs::read_dir(v.join("moved")).unwrap().count(), 2);
    }
}
