//! The `clevrtex` command-line tool. This file only parses arguments, dispatches and maps the
//! result to an exit code; the work lives in the library crates.

use std::process::ExitCode;

use clap::{Parser, Subcommand};
// The one font loader, also for the benchmark plot (`crate::font`).
use clevrtex_report::font;

mod cmd_bench;
mod cmd_doctor;
mod cmd_eval;
mod cmd_export;
mod cmd_generate;
mod cmd_materials;
mod cmd_preview;
mod cmd_render;
mod cmd_report;
mod cmd_sample;
mod cmd_verify;
mod estimate;
mod exit;
mod interrupt;
mod progress;
mod provenance;
mod run;
mod run_args;
mod suite;
mod user_materials;

/// Make and score texture-rich synthetic benchmarks for unsupervised multi-object
/// segmentation, in the style of ClevrTex.
#[derive(Debug, Parser)]
#[command(name = "clevrtex", version = provenance::VERSION_LINE, about, after_help = exit::EXIT_CODES_HELP)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Debug, Subcommand)]
enum Command {
    /// Sample scene layouts (JSON scene files) without rendering.
    Sample(cmd_sample::Args),
    /// Sample and render a dataset through Blender.
    Generate(Box<cmd_generate::GenerateArgs>),
    /// Render scene files made by `clevrtex sample`.
    Render(cmd_render::Args),
    /// Score predictions against a ground-truth dataset.
    Eval(cmd_eval::Args),
    /// List the material catalogue or render a contact sheet.
    Materials(cmd_materials::Args),
    /// Benchmarks: error against run time of render settings.
    Bench(cmd_bench::Args),
    /// Report the Blender found, its version, Cycles devices, and what is missing.
    Doctor(cmd_doctor::Args),
    /// Check that a dataset (or the union of shards) is complete and intact.
    Verify(cmd_verify::Args),
    /// Export a dataset as WebDataset tar shards.
    Export(cmd_export::Args),
    /// Draw a contact sheet of a dataset's samples and passes.
    Preview(cmd_preview::Args),
    /// Write an HTML report of a dataset's statistics (or two side by side).
    Report(cmd_report::Args),
}

fn main() -> ExitCode {
    // First, so that a signal at any moment of a run gets its exit code (130 / 143).
    interrupt::install_early();
    let cli = match Cli::try_parse() {
        Ok(cli) => cli,
        Err(err) => {
            let _ = err.print();
            return ExitCode::from(if err.use_stderr() {
                exit::USAGE
            } else {
                exit::OK
            });
        }
    };
    let result = match cli.command {
        Command::Sample(args) => cmd_sample::run(args),
        Command::Generate(args) => match &args.suite {
            Some(name) => suite::run(&args, name, args.scale.unwrap_or(1.0)),
            None => cmd_generate::run_generate(*args),
        },
        Command::Render(args) => cmd_render::run(args),
        Command::Eval(args) => cmd_eval::run(args),
        Command::Materials(args) => cmd_materials::run(args),
        Command::Bench(args) => cmd_bench::run(args),
        Command::Doctor(args) => cmd_doctor::run(args),
        Command::Verify(args) => cmd_verify::run(args),
        Command::Export(args) => cmd_export::run(args),
        Command::Preview(args) => cmd_preview::run(args),
        Command::Report(args) => cmd_report::run(args),
    };
    ExitCode::from(exit::report(result))
}
