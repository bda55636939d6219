//! `clevrtex generate --estimate`: the planner's command. It checks the request, has the
//! render crate's planner (`clevrtex_render::planner`) render a few calibration images of
//! the run's own settings (variant, size, samples, passes, device, workers x threads;
//! visibility pass and rejected layouts included) into a private scratch folder, never into
//! `--out`, and prints the predicted wall time, core or GPU hours and images/hour, alone and
//! as an array of tasks (SLURM `--array`, a Kubernetes Indexed Job's `completions`), with a
//! range from the calibration's spread (checks and text: `clevrtex_render::planner_text`).

use clevrtex_render::pool::Jobs;
use clevrtex_render::RenderError;
use clevrtex_render::{planner, planner_text};

use crate::exit::{self, CmdResult};
use crate::interrupt::{self, OnInterrupt};
use crate::run::pool_options;
use crate::run_args::RunArgs;

/// What `--estimate` was asked for.
pub(crate) struct Request<'a> {
    /// The run's options (`--out` is never written).
    pub run: &'a RunArgs,
    /// The run's jobs; a few are rendered.
    pub jobs: &'a Jobs,
    /// For the first line: variant, size, samples, passes.
    pub what: String,
    /// Calibration images (`--calibrate`), default 2 per worker, at least 4.
    pub calibrate: Option<u32>,
    /// Tasks of an array to predict as well (`--tasks`).
    pub tasks: Option<u64>,
    /// Layout attempts per image.
    pub max_attempts: u32,
    /// The catalogue (built-in plus `--materials`) and the materials the run's config names.
    pub materials: (
        clevrtex_materials::Catalogue,
        std::collections::BTreeSet<String>,
    ),
    /// A suite's sum of predictions (wall seconds, held hours), this one added to it.
    pub sum: Option<&'a std::cell::Cell<(f64, f64)>>,
}

/// Run the planner: calibrate, then print the predictions.
pub(crate) fn run(mut req: Request) -> CmdResult {
    let n = req.jobs.len();
    planner_text::check_request(req.calibrate, req.tasks, n, &req.run.out)
        .map_err(anyhow::Error::msg)?;
    let blender = clevrtex_render::blender::locate(req.run.blender.as_deref())?;
    let scratch = clevrtex_render::tmp::scratch_dir()?;
    let mut args = req.run.clone();
    args.out = scratch.path().join("out");
    args.overwrite = false;
    let interrupt = interrupt::flag(OnInterrupt::Stop {
        message: "stopping the calibration; nothing was written into `--out`",
    });
    let (catalogue, used) = &mut req.materials;
    let planned = pool_options(
        &args,
        (blender, None),
        scratch.path().join("failures.jsonl"),
        req.max_attempts,
        &interrupt,
        (catalogue, used),
    )?;
    let opts = &planned.opts;
    let k = planner_text::calibration_size(req.calibrate, opts.workers, n);
    eprintln!(
        "estimate: calibrating on {k} image(s) of {} with {} worker(s) in a scratch folder (nothing is written into `{}`)",
        req.what,
        opts.workers,
        req.run.out.display()
    );
    let made = match planner::calibrate(opts, req.jobs, k, &|line| eprintln!("{line}")) {
        Ok(m) => m,
        Err(RenderError::Interrupted) => {
            eprintln!(
                "error: {}\nhint: nothing was written into `--out`",
                exit::Interrupted
            );
            return Ok(crate::interrupt::exit_code());
        }
        Err(e) => return Err(e.into()),
    };
    let (text, p) =
        planner_text::report(&made, opts, (n, &req.what), req.tasks).map_err(anyhow::Error::msg)?;
    if let Some(sum) = req.sum {
        let (w, h) = sum.get();
        sum.set((w + p.wall_s, h + p.held_hours));
    }
    print!("{text}");
    drop(scratch);
    Ok(exit::OK)
}
