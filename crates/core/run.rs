//! The pool run of `generate` and `render`: the render crate's pool ([`pool::run`]) with the
//! options of [`RunArgs`], a progress bar, a line per event and the summary of the run.

use std::io::IsTerminal;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::Arc;
use std::time::Duration;

use anyhow::bail;
use clevrtex_render::manifest;
use clevrtex_render::pool::{self, Job, PoolEvent, PoolOptions, RunReport};
use clevrtex_render::RenderError;
use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};

use crate::exit::{self, CmdResult};
use crate::interrupt::{self, OnInterrupt};
use crate::run_args::{self, RunArgs};

/// Render `jobs` with the pool as `args` say, failures to `ledger`, with a progress bar (or a
/// line per sample when stderr is not a terminal) and a summary; with `manifest`, under the
/// range's lock, the plan written first and the manifest last.
pub(crate) fn run_jobs(
    args: &RunArgs,
    jobs: Vec<Job>,
    ledger: PathBuf,
    max_attempts: u32,
    manifest: Option<manifest::Plan>,
) -> CmdResult {
    let blender = clevrtex_render::blender::locate(args.blender.as_deref())?;
    check_output_writable(&args.out)?;
    let materials_json = clevrtex_render::default_materials_json()
        .map_err(|e| anyhow::anyhow!("the built-in material catalogue is invalid: {e}"))?;
    let interrupt = interrupt::flag(OnInterrupt::Stop {
        message: "stopping the workers; finished samples are kept",
    });
    if let Some(t) = args.timeout {
        if !(t > 0.0 && t.is_finite()) {
            bail!(
                "`--timeout {t}` must be a positive number of seconds\nhint: e.g. `--timeout 600`"
            );
        }
    }
    if args.workers == Some(0) {
        bail!("`--workers 0` cannot render anything\nhint: pass at least 1");
    }
    let choice = run_args::device_choice(&args.device)?;
    let startup_timeout = run_args::seconds("--startup-timeout", args.startup_timeout)?;
    let devices = clevrtex_render::gpu_probe::plan_devices(
        choice,
        &blender,
        &materials_json,
        startup_timeout,
        &interrupt,
    )?;
    if devices.iter().any(|d| d.is_gpu()) {
        let names: Vec<String> = devices.iter().map(|d| d.describe()).collect();
        eprintln!("devices: {}", names.join(", "));
    }
    if let Some(w) = clevrtex_render::device::kernel_compile_warning(&devices) {
        eprintln!("{w}");
    }
    let opts = PoolOptions {
        blender,
        materials_json,
        workers: args.workers.unwrap_or_else(|| {
            clevrtex_render::device::default_workers(&devices, pool::default_workers())
        }),
        threads: args.threads.unwrap_or(0),
        timeout: args.timeout.map(Duration::from_secs_f64),
        startup_timeout,
        retries: args.retries,
        max_attempts: max_attempts.max(1),
        visibility_check: true,
        keep_exr: args.keep_exr,
        overwrite: args.overwrite,
        fail_fast: args.fail_fast,
        out: args.out.clone(),
        ledger: ledger.clone(),
        interrupt: Arc::clone(&interrupt),
        devices: devices.clone(),
    };
    let total = jobs.len() as u64;
    let bar = progress_bar(total);
    let (done, rejects, failures) = (AtomicU64::new(0), AtomicU64::new(0), AtomicU64::new(0));
    let started = std::time::Instant::now();
    // Seconds per finished sample, by index, for the manifest (`clevrtex report` plots them).
    let seconds = std::sync::Mutex::new(std::collections::BTreeMap::<u64, f64>::new());
    let plain = bar.is_hidden();
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
            PoolEvent::WorkerStarted { .. } => {}
            PoolEvent::WorkerRestarted { error } => {
                say(format!("warning: restarting a Blender worker: {error}"));
            }
            PoolEvent::Rejected { .. } => {
                rejects.fetch_add(1, Ordering::Relaxed);
            }
            PoolEvent::Done { sample } => {
                let d = done.fetch_add(1, Ordering::Relaxed) + 1;
                let s =
                    sample.visibility_s + sample.reject_s + sample.final_request_s + sample.post_s;
                seconds
                    .lock()
                    .unwrap_or_else(|e| e.into_inner())
                    .insert(sample.index, s);
                bar.inc(1);
                if plain {
                    eprintln!(
                        "[{}/{}] wrote {}",
                        bar.position(),
                        total,
                        sample.metadata.display()
                    );
                }
                // Only fixed scene files (`render`) can get here with a hidden object:
                // `generate` resamples such layouts.
                let hidden: Vec<String> = (1..)
                    .zip(&sample.objects)
                    .filter(|(_, o)| o.pixels == 0)
                    .map(|(i, _)| i.to_string())
                    .collect();
                if !hidden.is_empty() {
                    say(format!(
                        "warning: object(s) {} of `{}` are hidden (not in the mask)\nhint: `clevrtex render` cannot resample fixed scene files; use `clevrtex generate` for layouts with every object visible",
                        hidden.join(", "),
                        sample.metadata.display()
                    ));
                }
                let _ = d;
            }
            PoolEvent::Failed { index, error } => {
                failures.fetch_add(1, Ordering::Relaxed);
                bar.inc(1);
                say(format!(
                    "error: image {index} failed (recorded in `{}`): {error}",
                    ledger.display()
                ));
            }
        }
        let d = done.load(Ordering::Relaxed);
        let per_hour = d as f64 / started.elapsed().as_secs_f64().max(1e-9) * 3600.0;
        bar.set_message(format!(
            "{per_hour:.0} img/h, {} rejects, {} failed",
            rejects.load(Ordering::Relaxed),
            failures.load(Ordering::Relaxed)
        ));
    };
    // One writer per range: a run whose indices overlap a live run's refuses here, before
    // anything is written; then the plan, so even a run that never ends is known to `verify`.
    let _lock = match &manifest {
        Some(plan) => {
            let lock = clevrtex_render::run_lock::RunLock::acquire(
                &plan.variant_dir(&args.out),
                plan.run.start,
                plan.run.end,
                plan.run.shard,
                std::env::args().collect(),
            )
            .map_err(|e| anyhow::anyhow!(e))?;
            // The lock made the variant folder (`layout::make_dir`: not a link out of `--out`).
            plan.write_plan(&args.out)?;
            write_card(&args.out);
            Some(lock)
        }
        None => None,
    };
    let result = pool::run(&opts, jobs, &on_event);
    bar.finish_and_clear();
    match result {
        Ok(report) => {
            print_summary(&report, &args.out, &ledger);
            if let Some(plan) = manifest {
                let seconds = seconds.into_inner().unwrap_or_else(|e| e.into_inner());
                let path = plan.write(&args.out, &seconds)?;
                write_card(&args.out);
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
        Err(RenderError::Interrupted) => {
            eprintln!(
                "error: {}\nhint: rerun the same command to go on; complete samples are skipped",
                exit::Interrupted
            );
            Ok(crate::interrupt::exit_code())
        }
        Err(e) => Err(e.into()),
    }
}

fn progress_bar(total: u64) -> ProgressBar {
    let target = if std::io::stderr().is_terminal() {
        ProgressDrawTarget::stderr()
    } else {
        ProgressDrawTarget::hidden()
    };
    let bar = ProgressBar::with_draw_target(Some(total), target);
    bar.set_style(
        ProgressStyle::with_template("{bar:24} {pos}/{len} images, {msg}, ETA {eta}")
            .expect("valid template"),
    );
    bar.set_message("0 img/h, 0 rejects, 0 failed");
    bar.enable_steady_tick(Duration::from_millis(500));
    bar
}

/// Make sure the output root exists and a file can be created in it, before any rendering.
fn check_output_writable(out: &Path) -> anyhow::Result<()> {
    let hint = "hint: pass a writable folder with `--out`";
    std::fs::create_dir_all(out).map_err(|e| {
        anyhow::anyhow!(
            "cannot create output folder `{}`: {e}\n{hint}",
            out.display()
        )
    })?;
    let probe = out.join(format!(".clevrtex-write-test-{}", std::process::id()));
    std::fs::write(&probe, b"").map_err(|e| {
        anyhow::anyhow!(
            "cannot write in output folder `{}`: {e}\n{hint}",
            out.display()
        )
    })?;
    let _ = std::fs::remove_file(probe);
    Ok(())
}

fn print_summary(r: &RunReport, out: &Path, ledger: &Path) {
    println!(
        "rendered {} images ({} already complete, {} failed) in {:.1} s with {} worker(s) x {} thread(s)",
        r.done,
        r.skipped,
        r.failed.len(),
        r.wall_s,
        r.workers,
        r.threads
    );
    if r.done > 0 {
        println!(
            "  {:.1} s per image, {:.0} images/hour",
            r.wall_s / r.done as f64,
            r.done as f64 / r.wall_s.max(1e-9) * 3600.0
        );
    }
    println!("time split (summed over workers):");
    println!(
        "  blender start    {:>8.1} s  ({} start(s))",
        r.blender_start_s, r.worker_starts
    );
    println!("  scene build      {:>8.1} s", r.build_s);
    println!(
        "  visibility pass  {:>8.1} s  (all {} passes incl. rejected: build {:.1} s, cycles {:.1} s)",
        r.visibility_s, r.visibility_passes, r.visibility_build_s, r.visibility_render_s
    );
    println!("  render (cycles)  {:>8.1} s", r.render_s);
    println!(
        "  bridge other     {:>8.1} s  (writing EXR/PNG in Blender, protocol)",
        (r.final_request_s - r.render_s - r.build_s).max(0.0)
    );
    println!("  post-processing  {:>8.1} s", r.post_s);
    println!(
        "  rejects          {:>8.1} s  ({} rejected layout(s); checked after the full render they would have cost ~{:.1} s)",
        r.reject_s,
        r.rejects,
        r.rejects_cost_if_checked_after()
    );
    if let Some(ratio) = r.overhead_ratio() {
        println!("  overhead: wall x workers / cycles render = {ratio:.3}");
    }
    println!("output: {}", out.display());
    if r.ledger_unreadable > 0 {
        eprintln!(
            "warning: dropped {} unreadable line(s) of the failure ledger `{}` (left by a run killed while writing it); rerun without `--overwrite` to find what is still missing",
            r.ledger_unreadable,
            ledger.display()
        );
    }
    if !r.failed.is_empty() {
        println!(
            "failures recorded in `{}`; rerun the same command to retry them",
            ledger.display()
        );
    }
}

/// Rewrite the dataset card from every run's manifest (`clevrtex_render::card`); a card that
/// cannot be written is a warning: the samples and the manifest are what the run made.
fn write_card(out: &std::path::Path) {
    if let Err(e) = clevrtex_render::card::write_card(out) {
        eprintln!("warning: the dataset card was not written: {e}");
    }
}
