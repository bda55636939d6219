//! What `generate` and `render` show of their run: the render crate's batch run
//! ([`batch::run`]) with the options of [`RunArgs`], a progress bar, a line per event and the
//! summary of the run.

use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::Arc;
use std::time::Duration;

use anyhow::bail;
use clevrtex_dataset::manifest;
use clevrtex_render::batch;
use clevrtex_render::kept::KeptWorkers;
use clevrtex_render::pool::PoolEvent;
use clevrtex_render::scene_jobs::RunJobs;

use crate::exit::{self, CmdResult};
use crate::interrupt::{self, OnInterrupt};
use crate::progress::progress_bar;
use crate::run_args::{self, RunArgs};
use clevrtex_render::run_text::{self, BatchProgress};

/// Render the jobs with the pool as `args` say, failures to their ledger, with a progress bar (or,
/// when stderr is not a terminal, a line per sample and a progress line with rate and ETA every
/// few images or minute: [`BatchProgress`]) and a summary; with `manifest`, the render crate's
/// batch run ([`batch::run`]: under the range's lock, the plan written first and the manifest
/// last). `catalogue` is the built-in one plus `--materials`; the user materials of it that
/// `used` names are checked before any image is rendered ([`batch::plan`]) and recorded in the
/// manifest and each sample's metadata. With `keep`, the workers of an earlier run of the
/// command serve this one where they started alike, and this run's are kept for the next
/// (`generate --suite`: [`clevrtex_render::kept`]).
pub(crate) fn run_jobs(
    args: &RunArgs,
    RunJobs { jobs, ledger, used }: RunJobs,
    max_attempts: u32,
    (manifest, keep): (Option<manifest::Plan>, Option<&Arc<KeptWorkers>>),
    mut catalogue: clevrtex_materials::Catalogue,
) -> CmdResult {
    // The numbers given as flags first: a refusal never waits on Blender.
    checked_numbers(args)?;
    let blender = clevrtex_render::blender::locate(args.blender.as_deref())?;
    clevrtex_dataset::atomic::check_writable(&args.out).map_err(anyhow::Error::msg)?;
    let interrupt = interrupt::flag(OnInterrupt::Stop {
        message: "stopping the workers; finished samples are kept",
    });
    let mut planned = pool_options(
        args,
        (blender, keep),
        ledger.clone(),
        max_attempts,
        &interrupt,
        (&mut catalogue, &used),
    )?;
    let total = jobs.len();
    let bar = progress_bar(total);
    let (done, rejects, failures) = (AtomicU64::new(0), AtomicU64::new(0), AtomicU64::new(0));
    let started = std::time::Instant::now();
    let plain = bar.is_hidden();
    let batch = BatchProgress::new(total);
    // A hidden bar swallows `println`: then messages go straight to stderr.
    let say = |msg: String| {
        if plain {
            eprintln!("{msg}");
        } else {
            bar.println(msg);
        }
    };
    let on_event = |ev: &PoolEvent| {
        match ev {
            PoolEvent::Skipped { .. } => bar.inc(1),
            PoolEvent::Rejected { .. } => {
                rejects.fetch_add(1, Ordering::Relaxed);
            }
            PoolEvent::Done { sample } => {
                done.fetch_add(1, Ordering::Relaxed);
                bar.inc(1);
                if plain {
                    eprintln!(
                        "[{}/{}] wrote {}",
                        bar.position(),
                        total,
                        sample.metadata.display()
                    );
                }
            }
            PoolEvent::Failed { .. } => {
                failures.fetch_add(1, Ordering::Relaxed);
                bar.inc(1);
            }
            _ => {}
        }
        if let Some(line) = run_text::event_line(ev, &ledger) {
            say(line);
        }
        let d = done.load(Ordering::Relaxed);
        if plain {
            let f = failures.load(Ordering::Relaxed);
            if let Some(line) = batch.event(bar.position(), d, f, started.elapsed()) {
                eprintln!("{line}");
            }
        }
        let per_hour = d as f64 / started.elapsed().as_secs_f64().max(1e-9) * 3600.0;
        bar.set_message(format!(
            "{per_hour:.0} img/h, {} rejects, {} failed",
            rejects.load(Ordering::Relaxed),
            failures.load(Ordering::Relaxed)
        ));
    };
    let warn = |line: String| eprintln!("{line}");
    let hooks = batch::Hooks {
        on_event: &on_event,
        warn: &warn,
    };
    // Without a terminal, a progress line also every `BatchProgress::EVERY` while images take
    // long: a ticker beside the run, stopped when it returns.
    let finished = std::sync::atomic::AtomicBool::new(false);
    let result = std::thread::scope(|s| {
        if plain {
            s.spawn(|| {
                while !finished.load(Ordering::Relaxed) {
                    std::thread::sleep(Duration::from_millis(250));
                    let (d, f) = (
                        done.load(Ordering::Relaxed),
                        failures.load(Ordering::Relaxed),
                    );
                    if let Some(line) = batch.tick(bar.position(), d, f, started.elapsed()) {
                        eprintln!("{line}");
                    }
                }
            });
        }
        let result = batch::run(
            &mut planned,
            jobs,
            manifest,
            std::env::args().collect(),
            &hooks,
        );
        finished.store(true, Ordering::Relaxed);
        result
    });
    bar.finish_and_clear();
    let interrupted = || {
        eprintln!(
            "error: {}\nhint: rerun the same command to go on; complete samples are skipped",
            exit::Interrupted
        );
        Ok(crate::interrupt::exit_code())
    };
    match result {
        Ok(batch::Ended::Finished { report, manifest }) => {
            print_summary(&report, &args.out, &ledger);
            if let Some(path) = manifest {
                println!(
                    "manifest: {} (check with `clevrtex verify {}`)",
                    path.display(),
                    args.out.display()
                );
            }
            Ok(if report.failed.is_empty() {
                exit::OK
            } else {
                exit::PARTIAL
            })
        }
        Ok(batch::Ended::Interrupted { report }) => {
            if let Some(report) = report {
                print_summary(&report, &args.out, &ledger);
            }
            interrupted()
        }
        Err(batch::RunError::Render(e)) => Err(crate::exit::command_error(e)),
        Err(batch::RunError::Dataset(e)) => Err(e.into()),
        Err(batch::RunError::Refused(m)) => Err(anyhow::anyhow!(m)),
    }
}

/// The numbers given as flags, checked (before Blender is looked for): `--timeout` and
/// `--startup-timeout` as durations, `--workers` in range.
pub(crate) fn checked_numbers(args: &RunArgs) -> anyhow::Result<(Option<Duration>, Duration)> {
    let timeout = args
        .timeout
        .map(|t| run_args::seconds("--timeout", t))
        .transpose()?;
    if args.workers == Some(0) {
        bail!("`--workers 0` cannot render anything\nhint: pass at least 1");
    }
    if let Some(w) = args.workers {
        let w = u32::try_from(w).unwrap_or(u32::MAX);
        clevrtex_scene::config::within("--workers", w, run_args::MAX_THREADS as u32)
            .map_err(anyhow::Error::msg)?;
    }
    let startup_timeout = run_args::seconds("--startup-timeout", args.startup_timeout)?;
    batch::memory_bound(args.max_worker_memory).map_err(anyhow::Error::msg)?;
    Ok((timeout, startup_timeout))
}

/// The pool's options for `args` ([`batch::plan`]: the user materials checked, the devices,
/// the workers and threads), its lines printed; `interrupt` stops it.
pub(crate) fn pool_options(
    args: &RunArgs,
    (blender, keep): (PathBuf, Option<&Arc<KeptWorkers>>),
    ledger: PathBuf,
    max_attempts: u32,
    interrupt: &Arc<std::sync::atomic::AtomicBool>,
    materials: (
        &mut clevrtex_materials::Catalogue,
        &std::collections::BTreeSet<String>,
    ),
) -> anyhow::Result<batch::Planned> {
    let (timeout, startup_timeout) = checked_numbers(args)?;
    let settings = batch::Settings {
        blender,
        device: run_args::device_choice(&args.device)?,
        workers: args.workers,
        threads: args.threads,
        timeout,
        startup_timeout,
        retries: args.retries,
        keep_exr: args.keep_exr,
        overwrite: args.overwrite,
        fail_fast: args.fail_fast,
        out: args.out.clone(),
        max_worker_memory: batch::memory_bound(args.max_worker_memory)
            .map_err(anyhow::Error::msg)?,
        recycle_after: args.recycle_after,
        keep: keep.cloned(),
    };
    let planned = batch::plan(&settings, ledger, max_attempts, interrupt, materials)
        .map_err(crate::exit::command_error)?;
    for line in &planned.notes {
        eprintln!("{line}");
    }
    Ok(planned)
}

/// The run's summary on stdout, its ledger's warning on stderr.
fn print_summary(report: &clevrtex_render::RunReport, out: &Path, ledger: &Path) {
    let (text, warning) = run_text::summary(report, out, ledger);
    print!("{text}");
    if let Some(w) = warning {
        eprintln!("{w}");
    }
}
