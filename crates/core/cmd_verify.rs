//! `clevrtex verify`: completeness and integrity of a dataset, or of the union of shards.

use std::path::PathBuf;

use anyhow::Context;
use clevrtex_dataset::verify::{self, Comparison, VariantReport, VerifyOptions};

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

/// Run `clevrtex verify`.
pub fn run(args: Args) -> CmdResult {
    let threads = args.jobs.unwrap_or(0);
    let started = std::time::Instant::now();
    if let Some(json) = &args.json {
        // The report is no file of the datasets it checks (a stray file there fails verify).
        let mut read: Vec<&std::path::Path> = args.dirs.iter().map(PathBuf::as_path).collect();
        read.extend(args.against.as_deref());
        clevrtex_dataset::out_path::check(json, "--json", &read).map_err(anyhow::Error::msg)?;
    }
    let opts = VerifyOptions {
        variant: args.variant.clone(),
    };
    let reports = verify::with_threads(threads, || verify::verify(&args.dirs, &opts))
        .map_err(anyhow::Error::msg)?
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
        print!(
            "{}",
            shown(&verify::report_text(r, &args.dirs, args.remove_broken))
        );
    }
    // A suite (`SUITE.json`) checked as a whole: none of its variants incomplete or foreign.
    let (suite_whole, text) =
        clevrtex_dataset::suite::verify_dirs(&args.dirs, &reports, args.variant.is_some())
            .map_err(anyhow::Error::msg)?;
    print!("{}", shown(&text));
    let secs = started.elapsed().as_secs_f64();
    eprintln!(
        "checked {samples} samples in {secs:.1} s ({:.0} samples/s)",
        samples as f64 / secs.max(1e-9)
    );
    let comparisons = match &args.against {
        Some(other) => verify::with_threads(threads, || {
            verify::against(&args.dirs, other, args.variant.as_deref())
        })
        .map_err(anyhow::Error::msg)?
        .map_err(|e| anyhow::anyhow!("--against: {e}"))?,
        None => Vec::new(),
    };
    for c in &comparisons {
        print!("{}", shown(&verify::comparison_text(c)));
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
            print!("{}", shown(&verify::removal_text(&r.variant, &done)));
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

/// What verify prints, which quotes both datasets' files (manifests, metadata, names): control
/// and bidirectional characters escaped, newlines kept (docs/security.md).
fn shown(text: &str) -> std::borrow::Cow<'_, str> {
    clevrtex_scene::text::printable_lines(text)
}
