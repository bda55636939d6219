//! `clevrtex preview DIR --out sheet.png`: parses the arguments, has
//! `clevrtex_report::preview` draw and write the contact sheet, and prints what was drawn and
//! what was left out.

use clevrtex_report::preview::{draw, save, Options, Sheet};

use crate::exit::{self, CmdResult};

/// Arguments of `clevrtex preview`.
#[derive(Debug, clap::Args)]
pub struct Args {
    #[command(flatten)]
    data: crate::run_args::DatasetDir,
    /// How many samples (the first N by index), unless `--indices` names them.
    #[arg(long, default_value_t = 16, value_parser = clap::value_parser!(u32).range(1..=256))]
    n: u32,
    /// These image indices, comma-separated.
    #[arg(long, value_delimiter = ',')]
    indices: Vec<u64>,
    /// Only this variant (when DIR holds several).
    #[arg(long)]
    variant: Option<String>,
    /// Width of one cell in pixels.
    #[arg(long, default_value_t = 192, value_parser = clap::value_parser!(u32).range(32..=1024))]
    cell: u32,
}

/// Run `clevrtex preview`.
pub fn run(args: Args) -> CmdResult {
    clevrtex_dataset::out_path::check(&args.data.out, "--out", &[&args.data.dir])
        .map_err(anyhow::Error::msg)?;
    let options = Options {
        dir: args.data.dir.clone(),
        n: args.n,
        indices: args.indices.clone(),
        variant: args.variant.clone(),
        cell: args.cell,
    };
    let Sheet {
        image: sheet,
        samples,
        columns,
        labelled: drew_text,
        problems,
        left_out,
    } = draw(&options)?;
    save(&sheet, &args.data.out)?;
    println!(
        "wrote `{}`: {} sample(s) x {} column(s) ({})",
        args.data.out.display(),
        samples,
        columns.len(),
        columns.join(", ")
    );
    if !drew_text {
        eprintln!(
            "warning: no TrueType font found (install fonts-dejavu-core): the sheet has no labels"
        );
    }
    for p in &left_out {
        eprintln!("left out the sample of {p}");
    }
    for p in &problems {
        eprintln!("skipped a cell of {p}");
    }
    if !problems.is_empty() || !left_out.is_empty() {
        eprintln!(
            "{} sample(s) left out, {} cell(s) left empty\nhint: `clevrtex verify` checks every file of the dataset",
            left_out.len(),
            problems.len()
        );
        return Ok(exit::PARTIAL);
    }
    Ok(exit::OK)
}
