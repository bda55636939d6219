//! `clevrtex report DIR --out report.html [--compare OTHER]`: parses the arguments, has
//! `clevrtex_report::report` read the datasets, build and write the page, and prints what
//! was read and left out. See `docs/report.md`.

use std::path::PathBuf;

use clevrtex_report::report::{make, write_page, Options};

use crate::exit::{self, CmdResult};

/// Arguments of `clevrtex report`.
#[derive(Debug, clap::Args)]
pub struct Args {
    #[command(flatten)]
    data: crate::run_args::DatasetDir,
    /// A second dataset to put beside the first, with a two-sample test per statistic.
    #[arg(long, value_name = "OTHER_DIR")]
    compare: Option<PathBuf>,
    /// Images per variant whose pixels are read (object contrast, depth range), evenly spread
    /// over the variant's indices; the metadata of every image is read regardless. 0 to
    /// 100000000.
    #[arg(long, default_value_t = 200, value_name = "N", value_parser = clap::builder::RangedU64ValueParser::<usize>::new().range(0..=100_000_000))]
    max_texture_samples: usize,
    /// Samples in the preview sheet.
    #[arg(long, default_value_t = 6, value_parser = clap::value_parser!(u32).range(0..=64))]
    preview: u32,
}

/// Run `clevrtex report`.
pub fn run(args: Args) -> CmdResult {
    if args.max_texture_samples == 0 {
        anyhow::bail!(
            "`--max-texture-samples 0` measures nothing\nhint: pass at least 1 (default 200)"
        );
    }
    let mut dirs = vec![args.data.dir.as_path()];
    dirs.extend(args.compare.as_deref());
    clevrtex_dataset::out_path::check(&args.data.out, "--out", &dirs)
        .map_err(anyhow::Error::msg)?;
    let started = std::time::Instant::now();
    let options = Options {
        max_texture_samples: args.max_texture_samples,
        preview: args.preview,
    };
    let report = make(&args.data.dir, args.compare.as_deref(), &options)?;
    write_page(&args.data.out, &report.html)?;
    println!(
        "wrote `{}` ({} KiB): {} image(s) read, {} measured, in {:.1} s",
        args.data.out.display(),
        report.html.len() / 1024,
        report.images,
        report.measured,
        started.elapsed().as_secs_f64()
    );
    let problems = report.problems;
    if !problems.is_empty() {
        for p in &problems {
            eprintln!("left out {p}");
        }
        eprintln!(
            "{} sample(s) or cell(s) left out of the report\nhint: `clevrtex verify` checks every file of the dataset",
            problems.len()
        );
        return Ok(exit::PARTIAL);
    }
    Ok(exit::OK)
}
