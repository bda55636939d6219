//! `clevrtex render`: render scene files made by `clevrtex sample`, through the same pool run
//! as `generate` (`run.rs`: [`run_jobs`]; its options [`RunArgs`] in `run_args.rs`); the scene
//! files are found and read by `clevrtex_dataset::scene_read`, their jobs made by
//! `clevrtex_render::scene_jobs`.

use std::path::PathBuf;

use crate::exit::{command_error, CmdResult};
use crate::run::run_jobs;
use crate::run_args::RunArgs;

/// Arguments of `clevrtex render`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// Scene files, or folders searched (recursively, as `clevrtex sample --out` lays them
    /// out) for `*.json` scene files.
    #[arg(required = true, value_name = "SCENES")]
    scenes: Vec<PathBuf>,
    #[command(flatten)]
    run: RunArgs,
}

/// Run `clevrtex render`.
pub fn run(args: Args) -> CmdResult {
    let files = clevrtex_dataset::scene_read::collect(&args.scenes, &mut |w| eprintln!("{w}"))
        .map_err(anyhow::Error::msg)?;
    let passes = match &args.run.passes {
        Some(list) => Some(clevrtex_scene::config::parse_passes(list).map_err(anyhow::Error::msg)?),
        None => None,
    };
    let catalogue = args.run.materials.catalogue()?;
    let r = clevrtex_render::scene_jobs::of_scene_files(files, &args.run.out, passes, &catalogue)
        .map_err(command_error)?;
    // One pool for every scene file, whatever its variant: its workers serve them all.
    run_jobs(&args.run, r, 1, (None, None), catalogue)
}
