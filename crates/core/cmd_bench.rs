//! `clevrtex bench render`: error against run time of Cycles settings. This file parses the
//! arguments, has the bench run (`clevrtex_bench::run`: Blender sessions, the ladder) and
//! prints what it measured.
//! See `docs/notes/performance.md`, section `bench`.

use std::collections::BTreeSet;
use std::path::{Path, PathBuf};

use anyhow::Context;
use clevrtex_bench::measure::Plan;
use clevrtex_bench::{csv, ladder, run, scenes, Row};

use crate::exit::{self, command_error_any, CmdResult};
use crate::interrupt::{self, OnInterrupt};

/// Arguments of `clevrtex bench`.
#[derive(Debug, clap::Args)]
pub struct Args {
    #[command(subcommand)]
    what: What,
}

#[derive(Debug, clap::Subcommand)]
enum What {
    /// Error against run time of render settings, against a cached high-sample reference.
    Render(RenderArgs),
}

/// Arguments of `clevrtex bench render`.
#[derive(Debug, clap::Args)]
pub struct RenderArgs {
    /// A few minutes instead of hours: 160x120, 2 scenes, fewer rungs, 1024-sample
    /// references. Numbers are for comparing settings, not for the docs' per-image costs.
    #[arg(long)]
    quick: bool,
    #[arg(long, value_name = "N", help = format!(
        "Number of scenes, 1 to 1024 (default 8, 2 with `--quick`); scene i is image i of the variant `{}` (cycling), seed {}",
        clevrtex_bench::scenes::VARIANTS.join(", "),
        clevrtex_bench::scenes::SEED
    ))]
    scenes: Option<usize>,
    /// Bench these scene files instead of the fixed scenes: files, or folders searched for
    /// `*.json` as `clevrtex render` takes them (e.g. `clevrtex sample` scenes whose backdrop
    /// has the most relief). Rendered at `--width` x `--height`; each scene's rows are named by
    /// its stem. At most 1024.
    #[arg(long = "scene", value_name = "SCENES", conflicts_with_all = ["scenes", "plot_only"])]
    scene_files: Vec<PathBuf>,
    /// Output folder: CSV, plot, renders and the reference cache.
    #[arg(long, default_value = "bench-out", value_name = "DIR")]
    out: PathBuf,
    /// Image width, 1 to 4096 (default 320, 160 with `--quick`).
    #[arg(long, value_parser = clap::value_parser!(u32).range(1..=4096))]
    width: Option<u32>,
    /// Image height, 1 to 4096 (default 240, 120 with `--quick`).
    #[arg(long, value_parser = clap::value_parser!(u32).range(1..=4096))]
    height: Option<u32>,
    /// Fixed samples of the reference renders (default 4096, 1024 with `--quick`), with the
    /// original generator's bounces; 1 to 65536.
    #[arg(long, value_name = "N", value_parser = clap::value_parser!(u32).range(1..=65536))]
    reference_samples: Option<u32>,
    /// Skip rungs with more samples than this (e.g. to try the command quickly).
    #[arg(long, value_name = "N")]
    max_samples: Option<u32>,
    /// Also the rungs of Cycles 4.x's levers (light tree off, path guiding, blue noise,
    /// OIDN-denoised RGB); needs a Blender 4.x or 5.x (e.g. `--blender .venv-bpy/bin/python`).
    #[arg(long)]
    levers: bool,
    /// Only rungs whose label contains one of these (comma-separated), e.g. `original,preset`.
    #[arg(long, value_delimiter = ',', value_name = "LIST")]
    only: Option<Vec<String>>,
    /// Render nothing: redraw the table, summary and plot from `OUT/bench-render.csv`.
    #[arg(long)]
    plot_only: bool,
    /// Cycles threads, 0 to 1024 (default 0: Blender's choice, all cores).
    #[arg(long, default_value_t = 0, value_name = "T", value_parser = clap::value_parser!(u32).range(0..=crate::run_args::MAX_THREADS as i64))]
    threads: u32,
    /// Restarts of a crashed or hung Blender worker per render before the bench stops (0 to
    /// 100).
    #[arg(long, default_value_t = 2, value_name = "N", value_parser = clap::value_parser!(u32).range(0..=crate::run_args::MAX_RETRIES as i64))]
    retries: u32,
    /// Time limit for a Blender worker to start (load the bridge and answer `ready`), seconds:
    /// more than 0, at most 604800.
    #[arg(long, default_value_t = clevrtex_render::STARTUP_TIMEOUT.as_secs_f64(), value_name = "SECONDS")]
    startup_timeout: f64,
    /// Blender: an executable, or a Python that imports `bpy` (default: `blender` on PATH, else
    /// `./.venv-bpy/bin/python`). Give it more than once to put Blenders side by side (each
    /// against its own reference, one after the other; the same one twice, e.g. `A B B A`,
    /// alternates runs against load drift and averages them).
    #[arg(long, env = "CLEVRTEX_BLENDER", value_name = "PATH")]
    blender: Vec<PathBuf>,
    /// With `--materials DIR`, the bench scenes draw their textured materials from the
    /// folder's user materials (same layouts): the per-image cost of a user library against
    /// the built-in catalogue.
    #[command(flatten)]
    materials: crate::user_materials::MaterialsArg,
}

/// Run `clevrtex bench`.
pub fn run(args: Args) -> CmdResult {
    match args.what {
        What::Render(a) => run_render(a),
    }
}

fn run_render(args: RenderArgs) -> CmdResult {
    let quick = args.quick;
    let files = if args.scene_files.is_empty() {
        Vec::new()
    } else {
        clevrtex_dataset::scene_read::collect(&args.scene_files, &mut |w| eprintln!("{w}"))
            .map_err(anyhow::Error::msg)?
    };
    if files.len() > clevrtex_bench::measure::MAX_SCENES {
        anyhow::bail!(
            "`--scene` found {} scene files, over {}\nhint: the bench compares a few scenes; pass some of them",
            files.len(),
            clevrtex_bench::measure::MAX_SCENES
        );
    }
    let plan = Plan::new(
        quick,
        if files.is_empty() {
            args.scenes
        } else {
            Some(files.len())
        },
        args.width,
        args.height,
        args.reference_samples,
    )?;
    if args.plot_only {
        let rows = csv::load(&args.out)?;
        let scenes: BTreeSet<&str> = rows.iter().map(|r| r.scene.as_str()).collect();
        let (w, h) = rows.first().map_or((0, 0), |r| (r.width, r.height));
        return report(&rows, scenes.len(), w, h, &args.out);
    }
    let settings = ladder::select(quick, args.levers, args.max_samples, args.only.as_deref())?;
    if let Some(big) = plan.oversampled(&settings) {
        eprintln!(
            "warning: rung `{}` has {} samples, not fewer than the reference's {}: its error is not meaningful",
            big.label, big.sampling.samples, plan.reference_samples
        );
    }
    let (n, width, height) = (plan.scenes, plan.width, plan.height);
    let mut catalogue = args.materials.catalogue()?;
    let user = args.materials.materials.as_ref().map(|_| &catalogue);
    let scenes = if files.is_empty() {
        scenes::bench_scenes_in(n, width, height, user)?
    } else {
        scenes::file_scenes(&files, width, height, &catalogue)?
    };
    std::fs::create_dir_all(&args.out).with_context(|| {
        format!(
            "cannot create output folder `{}`\nhint: pass a writable folder with `--out`",
            args.out.display()
        )
    })?;
    let opts = run::Options {
        blenders: &args.blender,
        threads: args.threads,
        retries: args.retries,
        startup_timeout: crate::run_args::seconds("--startup-timeout", args.startup_timeout)?,
        levers: args.levers,
        quick,
        out: &args.out,
        interrupt: interrupt::flag(OnInterrupt::Stop {
            message: "stopping Blender",
        }),
    };
    let rows = run::run(
        &opts,
        &mut catalogue,
        (&plan, &scenes, &settings),
        &mut |line| println!("{line}"),
        &mut |event| eprintln!("{event}"),
    )
    .map_err(command_error_any)?;
    csv::save(&rows, &args.out)?;
    report(&rows, n, width, height, &args.out)
}

/// Table and summary on stdout, plot next to the CSV.
fn report(rows: &[Row], n: usize, width: u32, height: u32, out: &Path) -> CmdResult {
    let fonts = crate::font::available();
    run::report(rows, (n, width, height), out, fonts, &mut |t| print!("{t}"))?;
    Ok(exit::OK)
}
