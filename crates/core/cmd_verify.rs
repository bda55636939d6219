//! `clevrtex verify`: completeness and integrity of a dataset, or of the union of shards.

use std::path::PathBuf;

use anyhow::Context;
use clevrtex_dataset::verify::{
    self, index_ranges, shell_words, Comparison, VariantReport, VerifyOptions,
};

use crate::exit::{self, CmdResult};

/// Arguments of `clevrtex verify`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// Output folders of `clevrtex generate` (`--out`), or `clevrtex_<variant>` folders; give
    /// every shard's folder to check their union.
    #[arg(required = true, value_name = "DIR")]
    dirs: Vec<PathBuf>,
    /// Check only this variant.
    #[arg(long)]
    variant: Option<String>,
    /// Delete the files of broken samples that a run of the manifests covers (only the names
    /// of the layout, inside the dataset) and the temporary files of dead writers, so that
    /// rerunning that run's `generate` command remakes them (duplicates are only reported).
    #[arg(long)]
    remove_broken: bool,
    /// Write the full report as JSON to FILE.
    #[arg(long, value_name = "FILE")]
    json: Option<PathBuf>,
    /// Also compare with another dataset made by the same command (its `--out` folder, or a
    /// folder of just its `clevrtex_<variant>/MANIFEST-*.json`): whether the two hold the same
    /// layouts, masks and metadata, image by image; RGB and other rendered passes that differ
    /// are counted as render noise, not failures (docs/runs.md, "Comparing two datasets").
    #[arg(long, value_name = "OTHER")]
    against: Option<PathBuf>,
    /// Threads, 1 to 1024 (default: all cores).
    #[arg(long, value_name = "N", value_parser = crate::run_args::threads_range::<usize>())]
    jobs: Option<usize>,
}

fn print_report(r: &VariantReport, dirs: &[PathBuf], remove: bool) {
    println!(
        "{}: {} of {} expected samples whole ({})",
        r.variant, r.ok, r.expected, r.expected_from
    );
    // What the dataset was made from, beyond the built-in catalogue (from the manifests).
    for (name, m) in &r.user_materials {
        let p = clevrtex_scene::text::printable;
        println!(
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
        println!("  splits: {}", sizes.join(", "));
    }
    if let Some(differ) = &r.loader_splits {
        println!("  warning: {differ}: `clevrtex eval --split` and the public loader and evaluator would use other sets\n  hint: remake the variant with one `--total` for every run (`generate --total N`), in a new folder");
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
        println!(
            "  missing ({}): {}{more}",
            r.missing_count,
            index_ranges(&r.missing)
        );
    }
    if !r.duplicates.is_empty() {
        println!("  duplicated indices ({}):", r.duplicates.len());
        for (i, places) in r.duplicates.iter().take(20) {
            let p: Vec<String> = places
                .iter()
                .map(|p| format!("`{}`", p.display()))
                .collect();
            println!("    {i} in {}", p.join(" and "));
        }
    }
    if !r.broken.is_empty() {
        println!("  broken samples ({}):", r.broken.len());
        for b in r.broken.iter().take(20) {
            println!("    {} (`{}`):", b.stem, b.dir.display());
            for p in &b.problems {
                println!("      {p}");
            }
        }
        if r.broken.len() > 20 {
            println!("    ... {} more (see --json)", r.broken.len() - 20);
        }
    }
    if !r.unexpected.is_empty() {
        println!(
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
            .and_then(|n| n.strip_suffix(clevrtex_dataset::layout::TMP_SUFFIX))
            .is_some_and(|stem| !clevrtex_dataset::atomic::tagged_name_is_stale(stem))
    });
    for (what, list) in [
        ("temporary files left by killed runs", dead),
        (
            "temporary files of runs still writing (or of another host; never removed)",
            live,
        ),
    ] {
        if !list.is_empty() {
            println!("  {what} ({}):", list.len());
            for t in list.iter().take(10) {
                println!("    {}", t.display());
            }
        }
    }
    if !r.skipped.is_empty() {
        println!("  not followed or not read ({}):", r.skipped.len());
        for s in r.skipped.iter().take(20) {
            println!("    {s}");
        }
        if r.skipped.len() > 20 {
            println!("    ... {} more (see --json)", r.skipped.len() - 20);
        }
    }
    for m in &r.mixed_on_purpose {
        println!("  settings mixed on purpose (`--mix-settings`): {m}");
    }
    for p in &r.manifest_problems {
        println!("  manifest: {p}");
    }
    if !r.ledger.is_empty() {
        let idx: Vec<u64> = r.ledger.keys().copied().collect();
        println!(
            "  failure ledger: {} image(s) recorded as failed: {}",
            idx.len(),
            index_ranges(&idx)
        );
        if let Some((i, e)) = r.ledger.iter().next() {
            println!("    e.g. {i}: {e}");
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
        if clevrtex_dataset::layout::variant_name_problem(&r.variant).is_some() {
            // A `clevrtex_<x>` folder no run could have written: no command repairs it.
            println!("  to repair: move or rename the folder named above; it is not a variant's folder and nothing in it was checked");
        } else if remove {
            println!("  to repair, rerun:\n    {rerun}");
        } else {
            println!(
                "  to repair: clevrtex verify {} --variant {} --remove-broken, then rerun:\n    {rerun}",
                dirs.join(" "),
                r.variant
            );
        }
    }
}

/// Print what `--against` found for one variant.
fn print_comparison(c: &Comparison) {
    let other = c.other.display();
    if !c.settings.is_empty() {
        println!(
            "{}: not comparable with `{other}`: made by another command ({}; this dataset's value first)\nhint: compare datasets made by the same `clevrtex generate` command (same variant, seed, config, size, samples, passes, materials, suite and `--total`)",
            c.variant,
            c.settings.join(", ")
        );
        return;
    }
    let noise: Vec<String> = c
        .render_noise
        .iter()
        .map(|(p, n)| format!("{p} {n}"))
        .collect();
    println!(
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
    if !c.fingerprints[0].is_empty() || !c.fingerprints[1].is_empty() {
        let show = |f: &str| {
            if f.is_empty() {
                "(not read)".to_string()
            } else {
                f.to_string()
            }
        };
        println!(
            "  layout fingerprints: {} here, {} there",
            show(&c.fingerprints[0]),
            show(&c.fingerprints[1])
        );
    }
    for d in &c.differ {
        println!("  differs: {d}");
    }
    if c.differ_count as usize > c.differ.len() {
        println!(
            "  ... {} more differ (see --json)",
            c.differ_count as usize - c.differ.len()
        );
    }
    if !c.only_here.is_empty() {
        println!(
            "  only here ({}): {}",
            c.only_here.len(),
            index_ranges(&c.only_here)
        );
    }
    if !c.only_there.is_empty() {
        println!(
            "  only in `{other}` ({}): {}",
            c.only_there.len(),
            index_ranges(&c.only_there)
        );
    }
    if c.same() {
        println!("  same layouts, masks and metadata");
    } else if c.compared == 0 && c.only_here.is_empty() && c.only_there.is_empty() {
        println!("  no finished image on either side to compare");
    }
}

/// The suite of `dirs` (`generate --suite`: their `SUITE.json`) checked as a whole: which
/// of its variants are incomplete or foreign; whether it is whole (`true` without a suite,
/// or with `--variant`, which checks one variant only).
fn check_suite(
    dirs: &[PathBuf],
    reports: &[VariantReport],
    one_variant: bool,
) -> anyhow::Result<bool> {
    let mut plan: Option<clevrtex_scene::suite::SuitePlan> = None;
    for d in dirs {
        let found = clevrtex_dataset::suite::read(d).map_err(anyhow::Error::msg)?;
        match (&plan, found) {
            (Some(p), Some(f)) if p != &f => anyhow::bail!(
                "the folders hold different suites (`{}` and `{}` at scales {} and {})\nhint: verify each suite's folders apart",
                p.suite, f.suite, p.scale, f.scale
            ),
            (None, Some(f)) => plan = Some(f),
            _ => {}
        }
    }
    let Some(plan) = plan else {
        return Ok(true);
    };
    if one_variant {
        return Ok(true);
    }
    let lines = clevrtex_dataset::suite::check(&plan, reports);
    if lines.is_empty() {
        println!(
            "suite `{}` at scale {}: whole ({} variants, {} images)",
            plan.suite,
            plan.scale,
            plan.variants.len(),
            plan.images()
        );
        return Ok(true);
    }
    println!(
        "suite `{}` at scale {}: incomplete variants ({} of {}):",
        plan.suite,
        plan.scale,
        lines.len(),
        plan.variants.len()
    );
    for l in &lines {
        println!("  {l}");
    }
    println!(
        "  to repair: rerun `clevrtex generate --suite {} --scale {} --seed {} --out DIR` (complete samples are skipped)",
        plan.suite, plan.scale, plan.seed
    );
    Ok(false)
}

/// Run `clevrtex verify`.
pub fn run(args: Args) -> CmdResult {
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(args.jobs.unwrap_or(0))
        .build()
        .context("cannot start worker threads")?;
    let started = std::time::Instant::now();
    let opts = VerifyOptions {
        variant: args.variant.clone(),
    };
    let reports = pool
        .install(|| verify::verify(&args.dirs, &opts))
        .map_err(|e| {
            anyhow::anyhow!("{e}\nhint: pass the `--out` folder of `clevrtex generate`")
        })?;
    if reports.is_empty() {
        anyhow::bail!(
            "no `clevrtex_<variant>` folder{} under {}\nhint: pass the `--out` folder of `clevrtex generate`",
            args.variant
                .as_ref()
                .map(|v| format!(" for `{v}`"))
                .unwrap_or_default(),
            args.dirs
                .iter()
                .map(|d| format!("`{}`", d.display()))
                .collect::<Vec<_>>()
                .join(", ")
        );
    }
    let samples: u64 = reports.iter().map(|r| r.ok + r.broken.len() as u64).sum();
    for r in &reports {
        print_report(r, &args.dirs, args.remove_broken);
    }
    let suite_whole = check_suite(&args.dirs, &reports, args.variant.is_some())?;
    let secs = started.elapsed().as_secs_f64();
    eprintln!(
        "checked {samples} samples in {secs:.1} s ({:.0} samples/s)",
        samples as f64 / secs.max(1e-9)
    );
    let comparisons = match &args.against {
        Some(other) => pool
            .install(|| verify::against(&args.dirs, other, args.variant.as_deref()))
            .map_err(|e| anyhow::anyhow!("--against: {e}"))?,
        None => Vec::new(),
    };
    for c in &comparisons {
        print_comparison(c);
    }
    if let Some(path) = &args.json {
        let text = if args.against.is_some() {
            serde_json::to_string_pretty(&serde_json::json!({
                "variants": reports,
                "against": comparisons,
            }))?
        } else {
            serde_json::to_string_pretty(&reports)?
        } + "\n";
        clevrtex_dataset::atomic::write(path, text.as_bytes())
            .with_context(|| format!("cannot write `{}`", path.display()))?;
    }
    if args.remove_broken {
        let mut removed = 0;
        for r in &reports {
            let done = verify::remove_broken(r).context("cannot remove a broken sample's file")?;
            removed += done.files;
            if !done.live.is_empty() {
                let idx: Vec<u64> = done.live.iter().map(|(i, _)| *i).collect();
                let mut runs: Vec<&str> = done.live.iter().map(|(_, h)| h.as_str()).collect();
                runs.dedup();
                println!(
                    "{}: left alone sample(s) {}: a live run is writing them ({})\nhint: run `clevrtex verify --remove-broken` again once that run has ended",
                    r.variant,
                    index_ranges(&idx),
                    runs.join("; ")
                );
            }
            if done.live_temps > 0 {
                println!(
                    "{}: left alone {} temporary file(s) of runs still writing",
                    r.variant, done.live_temps
                );
            }
            if !done.kept.is_empty() {
                println!(
                    "{}: kept broken sample(s) {}: no run of the manifests covers them, so no known command remakes them\nhint: remove them by hand if they are not wanted, or remake them with `clevrtex generate --start I -n N --out DIR`",
                    r.variant,
                    index_ranges(&done.kept)
                );
            }
        }
        println!("removed {removed} file(s) of broken samples and temporary files");
    }
    Ok(
        if suite_whole
            && reports.iter().all(VariantReport::is_whole)
            && comparisons.iter().all(Comparison::same)
        {
            exit::OK
        } else {
            exit::PARTIAL
        },
    )
}
