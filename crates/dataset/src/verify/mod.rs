//! `clevrtex verify`: is a dataset (one output folder, or the union of several shards' or runs'
//! folders) complete and intact?
//!
//! Per variant: every index of the runs present exactly once (the union of the manifests'
//! ranges, every run's plan included, else `0..=max` of what is there), every run finished,
//! every sample's metadata typed and naming the layout's files, every requested pass a PNG of
//! the right size and layout, mask ids exactly `0..=N` with every object above the visibility
//! threshold (recounted, and equal to the metadata), no temporary files, every file's bytes
//! equal to a manifest entry, and the failure ledger summarised. The dataset is walked and its
//! metadata typed by [`Dataset::open`] and [`crate::dataset::MetadataView`] (no link out of the dataset, only
//! regular files, capped), and every count taken from a file is bounded before it sizes
//! anything ([`MAX_RUN_INDICES`]).

//!
//! By concern: what it reports (`report.rs`), the checks of one sample (`checks.rs`), the
//! commands it offers to rerun and how it prints them (`command.rs`), `--remove-broken`
//! (`remove.rs`). Everything is re-exported here.

pub(crate) mod against;
pub(crate) mod checks;
pub(crate) mod command;
pub(crate) mod mixed;
pub(crate) mod rederive;
pub(crate) mod remove;
pub(crate) mod report;
pub(crate) mod resume;
#[cfg(test)]
mod tests;
pub(crate) mod text;

pub use against::{against, Comparison};
pub use command::{index_ranges, shell_words};
pub use mixed::run_differences;
pub use remove::*;
pub use report::*;
pub use resume::ResumeCheck;
pub use text::{comparison_text, removal_text, report_text};

use checks::*;
use command::*;

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};

use rayon::prelude::*;

use crate::dataset::{self, Dataset, VariantDir};
use crate::layout::{self};
use crate::manifest::{in_ranges, merge_ranges as merge, Manifest, MAX_RUN_INDICES};

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

/// `f` run on a pool of `threads` threads (0: one per core): `verify`'s walks and checks and
/// `against`'s comparisons are parallel.
pub fn with_threads<T: Send>(threads: usize, f: impl FnOnce() -> T + Send) -> Result<T, String> {
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .build()
        .map_err(|e| format!("cannot start worker threads: {e}"))?;
    Ok(pool.install(f))
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

/// Verify one variant found in `dirs` (each with the dataset it was found in): `verify`'s
/// report, also what every export leaves out ([`crate::export::samples`]).
pub(crate) fn verify_variant(variant: &str, dirs: &[(&Dataset, &VariantDir)]) -> VariantReport {
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
        if !rep.variant_dirs.contains(&vd.dir) {
            rep.variant_dirs.push(vd.dir.clone());
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
    let mut entries = Entries::default();
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
                entries.add(path, m);
            }
            // A shard with no index in the range (e.g. shard 1/2 of a one-image run, as a
            // suite's small variant gets) makes nothing and needs no manifest.
            let absent: Vec<String> = (0..(*n).min(1000))
                .filter(|k| !shards.contains(k))
                .filter(|&k| clevrtex_scene::shard::Shard { k, n: *n }.count(*start, *end) > 0)
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
        let (mixed, on_purpose) = mixed::mixed_runs(&manifests);
        rep.manifest_problems.extend(mixed);
        rep.mixed_on_purpose = on_purpose;
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
    // Each run's config rebuilt once, to draw its samples' layouts again.
    let configs: Configs = manifests
        .iter()
        .filter(|(_, m, _)| m.variant == variant)
        .map(|(p, m, _)| (p.clone(), rederive::config_of(m)))
        .collect();
    for (p, c) in &configs {
        if let Err(why) = c {
            rep.not_rederived.push(format!(
                "`{}`: {}",
                p.display(),
                clevrtex_scene::text::printable(why)
            ));
        }
    }
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
                &configs,
                &run_split(*index),
            )
        })
        .collect();
    let recorded: Vec<Option<layout::Split>> = checked.iter().map(|(s, _)| *s).collect();
    // The public loader cuts the samples it finds by position; where that differs from the
    // recorded splits, `eval --split` and the public evaluator score other sets. Said only of
    // a variant with no index missing: the loader refuses gaps.
    if rep.missing_count == 0 {
        rep.loader_splits = dataset::loader_disagreement(variant, &recorded);
    }
    for ((index, _, _), split) in singles.iter().zip(dataset::splits(variant, &recorded)) {
        let ranges = rep.splits.entry(split.name().to_string()).or_default();
        match ranges.last_mut() {
            Some(r) if r[1] + 1 == *index => r[1] = *index,
            _ => ranges.push([*index, *index]),
        }
    }
    let rederived = singles
        .iter()
        .filter(|(index, _, _)| {
            manifests.iter().any(|(p, m, _)| {
                m.variant == variant
                    && m.covers(*index)
                    && configs.get(p).is_some_and(Result::is_ok)
            })
        })
        .count() as u64;
    for ((index, _, _), (_, c)) in singles.iter().zip(checked) {
        match c {
            // A whole sample outside every run's indices is listed (`unexpected`), not
            // counted among the expected (a manifest far past the samples read "2 of 1").
            Ok(()) if in_ranges(&ranges, *index) => rep.ok += 1,
            Ok(()) => {}
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
                if remakes && m.suite.is_some() {
                    // A suite's `--shard` splits the whole suite, not this variant: the
                    // suite's command without a shard remakes what is missing.
                    push(command::without_shard(&c));
                } else if remakes {
                    push(with_shard(&c, k, n));
                }
            }
        }
    }
    rep.commands = commands;
    rep.rederived = rederived
        .saturating_sub(rep.broken.len() as u64)
        .min(rep.ok);
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
