//! What `clevrtex verify` prints, as text (the command prints it): a variant's report
//! ([`report_text`]: counts, splits, problems, what to repair) and what `--against` found
//! ([`comparison_text`]).

use std::fmt::Write;
use std::path::PathBuf;

use super::{index_ranges, shell_words, Comparison, VariantReport};

/// A variant's report as `verify` prints it; `dirs` and `remove` (`--remove-broken`) name the
/// repair.
pub fn report_text(r: &VariantReport, dirs: &[PathBuf], remove: bool) -> String {
    let mut out = String::new();
    let _ = writeln!(
        out,
        "{}: {} of {} expected samples whole ({})",
        r.variant, r.ok, r.expected, r.expected_from
    );
    if r.rederived > 0 {
        let _ = writeln!(
            out,
            "  {} sample(s) re-derived: their layouts drawn again from their run's seed and config equal their metadata",
            r.rederived
        );
    }
    for why in &r.not_rederived {
        let _ = writeln!(
            out,
            "  not re-derived (checked against the manifest's hashes and settings only): {why}"
        );
    }
    // What the dataset was made from, beyond the built-in catalogue (from the manifests).
    for (name, m) in &r.user_materials {
        let p = clevrtex_scene::text::printable;
        let _ = writeln!(
            out,
            "  user material {}: `{}`{}, {} texture(s), xxh3 {}",
            p(name),
            p(&m.file),
            m.group
                .as_deref()
                .map(|g| format!(" group `{}`", p(g)))
                .unwrap_or_default(),
            m.textures.len(),
            p(&m.xxh3)
        );
    }
    if !r.splits.is_empty() {
        // Each sample's split as every reader takes it (recorded, else by position).
        let sizes: Vec<String> = ["test", "val", "train"]
            .iter()
            .map(|s| {
                let n: u64 = r
                    .splits
                    .get(*s)
                    .map_or(0, |v| v.iter().map(|[a, b]| b - a + 1).sum());
                format!("{s} {n}")
            })
            .collect();
        let _ = writeln!(out, "  splits: {}", sizes.join(", "));
    }
    if let Some(differ) = &r.loader_splits {
        let _ = writeln!(out, "  warning: {differ}: `clevrtex eval --split` and the public loader and evaluator would use other sets\n  hint: remake the variant with one `--total` for every run (`generate --total N`), in a new folder");
    }
    if r.missing_count > 0 {
        // The list is capped (`verify::MAX_LISTED`); say where it stops.
        let more = match r.missing_count - r.missing.len() as u64 {
            0 => String::new(),
            n => format!(
                ", and {n} more after {} (not listed)",
                r.missing.last().unwrap_or(&0)
            ),
        };
        let _ = writeln!(
            out,
            "  missing ({}): {}{more}",
            r.missing_count,
            index_ranges(&r.missing)
        );
    }
    if !r.duplicates.is_empty() {
        let _ = writeln!(out, "  duplicated indices ({}):", r.duplicates.len());
        for (i, places) in r.duplicates.iter().take(20) {
            let p: Vec<String> = places
                .iter()
                .map(|p| format!("`{}`", p.display()))
                .collect();
            let _ = writeln!(out, "    {i} in {}", p.join(" and "));
        }
    }
    if !r.broken.is_empty() {
        let _ = writeln!(out, "  broken samples ({}):", r.broken.len());
        for b in r.broken.iter().take(20) {
            let _ = writeln!(out, "    {} (`{}`):", b.stem, b.dir.display());
            for p in &b.problems {
                let _ = writeln!(out, "      {p}");
            }
        }
        if r.broken.len() > 20 {
            let _ = writeln!(out, "    ... {} more (see --json)", r.broken.len() - 20);
        }
    }
    if !r.unexpected.is_empty() {
        let _ = writeln!(
            out,
            "  outside the run's indices ({}, not counted as errors): {}",
            r.unexpected.len(),
            index_ranges(&r.unexpected)
        );
    }
    // A temporary whose owner tag names a live process (or another host) is a file being
    // written now, not one left by a killed run.
    let (live, dead): (Vec<&PathBuf>, Vec<&PathBuf>) = r.temp_files.iter().partition(|t| {
        t.file_name()
            .and_then(|n| n.to_str())
            .and_then(|n| n.strip_suffix(crate::layout::TMP_SUFFIX))
            .is_some_and(|stem| !crate::atomic::tagged_name_is_stale(stem))
    });
    for (what, list) in [
        ("temporary files left by killed runs", dead),
        (
            "temporary files of runs still writing (or of another host; never removed)",
            live,
        ),
    ] {
        if !list.is_empty() {
            let _ = writeln!(out, "  {what} ({}):", list.len());
            for t in list.iter().take(10) {
                let _ = writeln!(out, "    {}", t.display());
            }
        }
    }
    if !r.skipped.is_empty() {
        let _ = writeln!(out, "  not followed or not read ({}):", r.skipped.len());
        for s in r.skipped.iter().take(20) {
            let _ = writeln!(out, "    {s}");
        }
        if r.skipped.len() > 20 {
            let _ = writeln!(out, "    ... {} more (see --json)", r.skipped.len() - 20);
        }
    }
    for m in &r.mixed_on_purpose {
        let _ = writeln!(out, "  settings mixed on purpose (`--mix-settings`): {m}");
    }
    for p in &r.manifest_problems {
        let _ = writeln!(out, "  manifest: {p}");
    }
    if !r.ledger.is_empty() {
        let idx: Vec<u64> = r.ledger.keys().copied().collect();
        let _ = writeln!(
            out,
            "  failure ledger: {} image(s) recorded as failed: {}",
            idx.len(),
            index_ranges(&idx)
        );
        if let Some((i, e)) = r.ledger.iter().next() {
            let _ = writeln!(out, "    e.g. {i}: {e}");
        }
    }
    if !r.is_whole() {
        let dirs: Vec<String> = dirs.iter().map(|d| d.display().to_string()).collect();
        let rerun = match r.commands.as_slice() {
            [] => {
                "rerun the `clevrtex generate` command that made it (complete samples are skipped)"
                    .to_string()
            }
            cmds => cmds
                .iter()
                .map(|c| shell_words(c))
                .collect::<Vec<_>>()
                .join("\n    "),
        };
        if crate::layout::variant_name_problem(&r.variant).is_some() {
            // A `clevrtex_<x>` folder no run could have written: no command repairs it.
            let _ = writeln!(out, "  to repair: move or rename the folder named above; it is not a variant's folder and nothing in it was checked");
        } else if remove {
            let _ = writeln!(out, "  to repair, rerun:\n    {rerun}");
        } else {
            let _ = writeln!(
                out,
                "  to repair: clevrtex verify {} --variant {} --remove-broken, then rerun:\n    {rerun}",
                dirs.join(" "),
                r.variant
            );
        }
    }
    out
}

/// What `--against` found for one variant, as `verify` prints it.
pub fn comparison_text(c: &Comparison) -> String {
    let mut out = String::new();
    let other = c.other.display();
    if !c.settings.is_empty() {
        let _ = writeln!(
                out,
            "{}: not comparable with `{other}`: made by another command ({}; this dataset's value first)\nhint: compare datasets made by the same `clevrtex generate` command (same variant, seed, config, size, samples, passes, materials, suite and `--total`)",
            c.variant,
            c.settings.join(", ")
        );
        return out;
    }
    let noise: Vec<String> = c
        .render_noise
        .iter()
        .map(|(p, n)| format!("{p} {n}"))
        .collect();
    let _ = writeln!(
                out,
        "{}: against `{other}`: {} of {} image(s) in both hold the same layout, mask and metadata{}",
        c.variant,
        c.identical,
        c.compared,
        if noise.is_empty() {
            String::new()
        } else {
            format!(
                "; rendered passes differ (render noise, not a failure): {}",
                noise.join(", ")
            )
        }
    );
    for (claims, side) in c
        .claims_only
        .iter()
        .zip(["this dataset", "the other dataset"])
    {
        if *claims {
            let _ = writeln!(
                out,
                "  compared with {side}'s manifests' claims, not its files: no sample's files were found there, so nothing about its files is proven"
            );
        }
    }
    if !c.fingerprints[0].is_empty() || !c.fingerprints[1].is_empty() {
        let show = |f: &str| {
            if f.is_empty() {
                "(not read)".to_string()
            } else {
                f.to_string()
            }
        };
        let _ = writeln!(
            out,
            "  layout fingerprints: {} here, {} there",
            show(&c.fingerprints[0]),
            show(&c.fingerprints[1])
        );
    }
    for d in &c.differ {
        let _ = writeln!(out, "  differs: {d}");
    }
    if c.differ_count as usize > c.differ.len() {
        let _ = writeln!(
            out,
            "  ... {} more differ (see --json)",
            c.differ_count as usize - c.differ.len()
        );
    }
    if !c.only_here.is_empty() {
        let _ = writeln!(
            out,
            "  only here ({}): {}",
            c.only_here.len(),
            index_ranges(&c.only_here)
        );
    }
    if !c.only_there.is_empty() {
        let _ = writeln!(
            out,
            "  only in `{other}` ({}): {}",
            c.only_there.len(),
            index_ranges(&c.only_there)
        );
    }
    if c.same() && c.claims_only.iter().any(|x| *x) {
        let _ = writeln!(out, "  the same layouts, masks and metadata claimed");
    } else if c.same() {
        let _ = writeln!(out, "  same layouts, masks and metadata");
    } else if !c.fingerprints[0].is_empty()
        && !c.fingerprints[1].is_empty()
        && c.fingerprints[0] != c.fingerprints[1]
    {
        let _ = writeln!(
            out,
            "  the layout fingerprints differ: not the same layouts"
        );
    } else if c.compared == 0 && c.only_here.is_empty() && c.only_there.is_empty() {
        let _ = writeln!(out, "  no finished image on either side to compare");
    }
    out
}

/// What `--remove-broken` left alone of variant `variant` (`done`), as `verify` prints it.
pub fn removal_text(variant: &str, done: &super::Removal) -> String {
    let mut out = String::new();
    if !done.live.is_empty() {
        let idx: Vec<u64> = done.live.iter().map(|(i, _)| *i).collect();
        let mut runs: Vec<&str> = done.live.iter().map(|(_, h)| h.as_str()).collect();
        runs.dedup();
        let _ = writeln!(
            out,
            "{variant}: left alone sample(s) {}: a live run is writing them ({})\nhint: run `clevrtex verify --remove-broken` again once that run has ended",
            index_ranges(&idx),
            runs.join("; ")
        );
    }
    if done.live_temps > 0 {
        let _ = writeln!(
            out,
            "{variant}: left alone {} temporary file(s) of runs still writing",
            done.live_temps
        );
    }
    if !done.kept.is_empty() {
        let _ = writeln!(
            out,
            "{variant}: kept broken sample(s) {}: no run of the manifests covers them, so no known command remakes them\nhint: remove them by hand if they are not wanted, or remake them with `clevrtex generate --start I -n N --out DIR`",
            index_ranges(&done.kept)
        );
    }
    out
}
