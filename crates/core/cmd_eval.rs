//! `clevrtex eval`.

use std::path::{Path, PathBuf};

use clevrtex_eval::{evaluate, output, Metric, Options, Protocol, Split};

use crate::exit::{CmdResult, OK};

/// Arguments of `clevrtex eval`.
#[derive(Debug, clap::Args)]
#[command(
    after_help = "Predictions are found anywhere under PREDS by the ground-truth stem \
`CLEVRTEX_<variant>_<index:06>`: `<stem>_mask.png` (segment ids), `<stem>.npy` or `<stem>.npz` \
(`labels` (H, W) or `masks` (K, H, W), optional `recon`), and `<stem>_recon.png` for MSE. \
Metric definitions: docs/eval.md.\n\nExit codes: 0 ok, 1 error (missing or malformed \
predictions, shape mismatch, damaged ground truth), 2 usage error"
)]
pub struct Args {
    /// Directory holding the predictions (searched recursively).
    pub preds: PathBuf,
    /// Ground-truth dataset directory in the published layout.
    pub gt: PathBuf,
    #[arg(long, help = format!(
        "Variant name in the file names ({}, ...); inferred when the dataset holds one",
        clevrtex_scene::config::Config::variant_list()
    ))]
    pub variant: Option<String>,
    /// Which samples to score: each sample's recorded split (by position where none is recorded) [default: test; all for outd].
    #[arg(long, value_enum)]
    pub split: Option<SplitArg>,
    /// Whose metrics to report by default, and the crop: `clevrtex` (the public ClevrTex
    /// evaluator; crop the centre 80% square and resize to 128x128), `native` (the same metrics,
    /// no resize), `deepmind` (FG-ARI of multi_object_datasets), `ocl` (ARI, mIoU, mBO, CorLoc of
    /// the object-centric learning framework); see docs/eval.md.
    #[arg(long, value_enum, default_value = "clevrtex")]
    pub protocol: ProtocolArg,
    /// Metrics to report, by name, comma-separated, from any protocol (`all` for every one)
    /// [default: the protocol's].
    #[arg(long, value_name = "A,B,C", value_delimiter = ',', value_parser = parse_metric)]
    pub metrics: Vec<MetricSel>,
    /// Score at the dataset's own resolution (no crop, no resize) under any protocol.
    #[arg(long)]
    pub native_size: bool,
    /// Soft masks hold foreground slots only: put a background `1 - sum(masks)` in front.
    #[arg(long)]
    pub no_background: bool,
    /// Score samples without a prediction as all-background (counted in the report).
    #[arg(long)]
    pub allow_missing: bool,
    /// Bootstrap resamples for the 95% confidence intervals, 0 to 100000 (0 to skip).
    #[arg(long, default_value_t = 1000)]
    pub bootstrap: usize,
    /// Seed of the bootstrap.
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Write the report as JSON to FILE.
    #[arg(long, value_name = "FILE")]
    pub json: Option<PathBuf>,
    /// Write one CSV row per image to FILE.
    #[arg(long, value_name = "FILE")]
    pub csv: Option<PathBuf>,
}

/// `--split` values.
#[derive(Clone, Copy, Debug, clap::ValueEnum)]
pub enum SplitArg {
    /// First 10%.
    Test,
    /// Next 10%.
    Val,
    /// Remaining 80%.
    Train,
    /// Every sample.
    All,
}

/// `--protocol` values.
#[derive(Clone, Copy, Debug, clap::ValueEnum)]
pub enum ProtocolArg {
    /// The public ClevrTex evaluator's metrics; the benchmark's crop and resize to 128x128.
    Clevrtex,
    /// The same metrics at the dataset's own resolution.
    Native,
    /// DeepMind's FG-ARI (multi_object_datasets).
    Deepmind,
    /// The object-centric learning framework's ARI, mIoU, mBO and CorLoc.
    Ocl,
}

/// One `--metrics` entry: a metric, or `all`.
#[derive(Clone, Debug)]
pub enum MetricSel {
    /// Every metric.
    All,
    /// One metric.
    One(Metric),
}

fn parse_metric(s: &str) -> Result<MetricSel, String> {
    if s == "all" {
        return Ok(MetricSel::All);
    }
    Metric::from_name(s).map(MetricSel::One).ok_or_else(|| {
        let names: Vec<&str> = Metric::ALL.iter().map(|m| m.name()).collect();
        format!("unknown metric `{s}`; known: {}, all", names.join(", "))
    })
}

/// Write `text` to `path` with the one atomic writer ([`clevrtex_dataset::atomic`]): a unique
/// temporary, never a link followed, no partial file or temporary left behind.
fn write_atomic(path: &Path, text: &str) -> anyhow::Result<()> {
    clevrtex_dataset::atomic::write(path, text.as_bytes()).map_err(|e| {
        anyhow::anyhow!(
            "cannot write `{}`: {e}\nhint: check that FILE is not a directory and that its directory exists and is writable",
            path.display()
        )
    })
}

/// Run `clevrtex eval`.
pub fn run(args: Args) -> CmdResult {
    // Before the (long) evaluation: no report is written into the ground-truth dataset. The
    // predictions' folder is the user's own, not a dataset: a report beside them (`preds/r.json`)
    // is read by nothing that reads predictions (`<stem>_mask.png|.npy|.npz`).
    for (flag, path) in [("--json", &args.json), ("--csv", &args.csv)] {
        if let Some(p) = path {
            clevrtex_dataset::out_path::check(p, flag, &[&args.gt]).map_err(anyhow::Error::msg)?;
        }
    }
    let opts = Options {
        protocol: match args.protocol {
            ProtocolArg::Clevrtex => Protocol::Clevrtex,
            ProtocolArg::Native => Protocol::Native,
            ProtocolArg::Deepmind => Protocol::Deepmind,
            ProtocolArg::Ocl => Protocol::Ocl,
        },
        metrics: {
            let mut chosen: Vec<Metric> = Vec::new();
            for sel in &args.metrics {
                let add: &[Metric] = match sel {
                    MetricSel::All => &Metric::ALL,
                    MetricSel::One(m) => std::slice::from_ref(m),
                };
                for m in add {
                    if !chosen.contains(m) {
                        chosen.push(*m);
                    }
                }
            }
            chosen
        },
        native_size: args.native_size,
        split: args.split.map(|s| match s {
            SplitArg::Test => Split::Test,
            SplitArg::Val => Split::Val,
            SplitArg::Train => Split::Train,
            SplitArg::All => Split::All,
        }),
        variant: args.variant,
        no_background: args.no_background,
        allow_missing: args.allow_missing,
        bootstrap: args.bootstrap,
        seed: args.seed,
    };
    // A flag that does not fit the dataset (e.g. `--split val` on `outd`) or its limit
    // (`--bootstrap`) is an error (1) with a hint, as in every command: 2 is only for a
    // command line the parser rejects (README, "Exit codes").
    let report = evaluate(&args.preds, &args.gt, &opts)?;
    if let Some(path) = &args.json {
        let json = output::to_json(&report, env!("CARGO_PKG_VERSION"));
        write_atomic(path, &format!("{json:#}\n"))?;
    }
    if let Some(path) = &args.csv {
        write_atomic(path, &output::to_csv(&report))?;
    }
    print!(
        "{}",
        clevrtex_scene::text::printable_lines(&output::to_table(&report))
    );
    for line in output::warnings(&report) {
        eprintln!("{}", clevrtex_scene::text::printable_lines(&line));
    }
    Ok(OK)
}
