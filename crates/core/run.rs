//! What `generate` and `render` show of their run: the render crate's batch run
//! ([`batch::run`]) with the options of [`RunArgs`], a progress bar, a line per event and the
//! summary of the run.

use std::io::IsTerminal;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::Arc;
use std::time::Duration;

use anyhow::bail;
use clevrtex_dataset::manifest;
use clevrtex_render::batch;
use clevrtex_render::pool::{Jobs, PoolEvent, RunReport};
use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};

use crate::exit::{self, CmdResult};
use crate::interrupt::{self, OnInterrupt};
use crate::run_args::{self, RunArgs};

/// Render `jobs` with the pool as `args` say, failures to `ledger`, with a progress bar (or,
/// when stderr is not a terminal, a line per sample and a progress line with rate and ETA every
/// few images or minute: [`BatchProgress`]) and a summary; with `manifest`, the render crate's
/// batch run ([`batch::run`]: under the range's lock, the plan written first and the manifest
/// last). `catalogue` is the built-in one plus `--materials`; the user materials of it that
/// `used` names are checked before any image is rendered ([`batch::plan`]) and recorded in the
/// manifest and each sample's metadata.
pub(crate) fn run_jobs(
    args: &RunArgs,
    jobs: Jobs,
    ledger: PathBuf,
    max_attempts: u32,
    manifest: Option<manifest::Plan>,
    (mut catalogue, used): (
        clevrtex_materials::Catalogue,
        std::collections::BTreeSet<String>,
    ),
) -> CmdResult {
    // The numbers given as flags first: a refusal never waits on Blender.
    checked_numbers(args)?;
    let blender = clevrtex_render::blender::locate(args.blender.as_deref())?;
    check_output_writable(&args.out)?;
    let interrupt = interrupt::flag(OnInterrupt::Stop {
        message: "stopping the workers; finished samples are kept",
    });
    let mut planned = pool_options(
        args,
        blender,
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
            PoolEvent::WorkerStarted { .. } => {}
            PoolEvent::WorkerRestarted { error } => {
                say(format!("warning: restarting a Blender worker: {error}"));
            }
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
            }
            PoolEvent::WorkerRecycled { rss, images, why } => {
                let mem = rss
                    .map(|r| format!(", {} MiB resident", r >> 20))
                    .unwrap_or_default();
                say(format!(
                    "note: a Blender worker made {images} image(s){mem} and was recycled ({}); the next image starts a fresh one",
                    if *why == "memory" {
                        "past `--max-worker-memory`"
                    } else {
                        "`--recycle-after`"
                    }
                ));
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
        if plain {
            batch.event(
                bar.position(),
                d,
                failures.load(Ordering::Relaxed),
                started.elapsed(),
            );
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
                    batch.tick(
                        bar.position(),
                        done.load(Ordering::Relaxed),
                        failures.load(Ordering::Relaxed),
                        started.elapsed(),
                    );
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
fn checked_numbers(args: &RunArgs) -> anyhow::Result<(Option<Duration>, Duration)> {
    let timeout = args
        .timeout
        .map(|t| run_args::seconds("--timeout", t))
        .transpose()?;
    if args.workers == Some(0) {
        bail!("`--workers 0` cannot render anything\nhint: pass at least 1");
    }
    if let Some(w) = args.workers {
        let w = u32::try_from(w).unwrap_or(u32::MAX);
        run_args::within("--workers", w, run_args::MAX_THREADS as u32)?;
    }
    let startup_timeout = run_args::seconds("--startup-timeout", args.startup_timeout)?;
    Ok((timeout, startup_timeout))
}

/// The pool's options for `args` ([`batch::plan`]: the user materials checked, the devices,
/// the workers and threads), its lines printed; `interrupt` stops it.
pub(crate) fn pool_options(
    args: &RunArgs,
    blender: PathBuf,
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
        max_worker_memory: match args.max_worker_memory {
            Some(g) if !(g > 0.0 && g <= 1e6) => bail!(
                "`--max-worker-memory {g}` is out of range\nhint: pass the GiB a worker may hold, more than 0 (e.g. 8)"
            ),
            Some(g) => Some((g * (1u64 << 30) as f64) as u64),
            None => None,
        },
        recycle_after: args.recycle_after,
    };
    let planned = batch::plan(&settings, ledger, max_attempts, interrupt, materials)
        .map_err(crate::exit::command_error)?;
    for line in &planned.notes {
        eprintln!("{line}");
    }
    Ok(planned)
}

/// The progress lines of a batch log (stderr not a terminal): `progress: 40/200 images (38
/// written, 2 failed), 912 img/h, ETA 10m 31s`, at most every [`Self::EVERY_IMAGES`]
/// images or 5% of the run (whichever is more), and every [`Self::EVERY`] while nothing ends.
struct BatchProgress {
    total: u64,
    every_images: u64,
    /// (position, when) of the last line.
    last: std::sync::Mutex<(u64, Duration)>,
}

impl BatchProgress {
    /// Images between two lines, at least (more on large runs: 5% of them).
    const EVERY_IMAGES: u64 = 10;
    /// The longest time between two lines while images are still being made.
    const EVERY: Duration = Duration::from_secs(60);

    fn new(total: u64) -> Self {
        BatchProgress {
            total,
            every_images: (total / 20).max(Self::EVERY_IMAGES.min(total.max(1))),
            last: std::sync::Mutex::new((0, Duration::ZERO)),
        }
    }

    /// After an image ended (`position` counted, skipped ones included): a line when enough
    /// images ended since the last one, or at the last image.
    fn event(&self, position: u64, done: u64, failed: u64, elapsed: Duration) {
        let mut last = self.last.lock().unwrap_or_else(|e| e.into_inner());
        if position >= last.0 + self.every_images || (position == self.total && last.0 < position) {
            *last = (position, elapsed);
            eprintln!(
                "{}",
                progress_line(position, self.total, done, failed, elapsed)
            );
        }
    }

    /// Every so often: a line when [`Self::EVERY`] passed since the last one.
    fn tick(&self, position: u64, done: u64, failed: u64, elapsed: Duration) {
        let mut last = self.last.lock().unwrap_or_else(|e| e.into_inner());
        if elapsed >= last.1 + Self::EVERY && position < self.total {
            *last = (position, elapsed);
            eprintln!(
                "{}",
                progress_line(position, self.total, done, failed, elapsed)
            );
        }
    }
}

/// One progress line: `position` of `total` images ended (written, already complete or
/// failed), `done` written and `failed` failed by this run in `elapsed`; the rate counts the
/// images this run ended, the ETA is the images left at that rate.
fn progress_line(position: u64, total: u64, done: u64, failed: u64, elapsed: Duration) -> String {
    let secs = elapsed.as_secs_f64().max(1e-9);
    let per_hour = done as f64 / secs * 3600.0;
    let ended = done + failed;
    let left = total.saturating_sub(position);
    let eta = if left == 0 {
        "0s".to_string()
    } else if ended == 0 {
        "unknown".to_string()
    } else {
        format_duration(secs / ended as f64 * left as f64)
    };
    let skipped = position.saturating_sub(ended);
    format!(
        "progress: {position}/{total} images ({done} written{}, {failed} failed), {per_hour:.0} img/h, elapsed {}, ETA {eta}",
        if skipped > 0 {
            format!(", {skipped} already complete")
        } else {
            String::new()
        },
        format_duration(secs)
    )
}

/// `3h 05m`, `12m 31s`, `42s`.
pub(crate) fn format_duration(secs: f64) -> String {
    let s = secs.max(0.0).round() as u64;
    match s {
        0..=59 => format!("{s}s"),
        60..=3599 => format!("{}m {:02}s", s / 60, s % 60),
        _ => format!("{}h {:02}m", s / 3600, s % 3600 / 60),
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
    // A temporary of the one atomic writer, dropped unrenamed: nothing is left, and nothing
    // planted there is written through or removed.
    clevrtex_dataset::atomic::AtomicFile::create(&out.join(".clevrtex-write-test")).map_err(
        |e| {
            anyhow::anyhow!(
                "cannot write in output folder `{}`: {e}\n{hint}",
                out.display()
            )
        },
    )?;
    Ok(())
}

/// The bridge's phases (every request, rejects included), CPU and wall seconds; nothing from
/// a bridge that does not report them.
fn print_phases(p: &clevrtex_render::BridgePhases) {
    if p.cpu_s() <= 0.0 {
        return;
    }
    let parts: Vec<String> = p
        .named()
        .iter()
        .filter(|(_, t)| t.cpu_s > 0.0 || t.wall_s > 0.0)
        .map(|(name, t)| format!("{name} {:.1}/{:.1}", t.cpu_s, t.wall_s))
        .collect();
    println!(
        "  bridge phases    {:>8.1} CPU-s  (CPU/wall s: {})",
        p.cpu_s(),
        parts.join(", ")
    );
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
    print_phases(&r.phases);
    println!(
        "  rejects          {:>8.1} s  ({} rejected layout(s), {} from the geometry without a visibility pass; checked after the full render they would have cost ~{:.1} s)",
        r.reject_s,
        r.rejects,
        r.prerejects,
        r.rejects_cost_if_checked_after()
    );
    if r.peak_rss > 0 {
        println!(
            "  worker memory    {:>8} MiB peak resident between images{}",
            r.peak_rss >> 20,
            if r.recycled > 0 {
                format!("; {} worker(s) recycled", r.recycled)
            } else {
                String::new()
            }
        );
    }
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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn progress_lines_give_rate_eta_and_failures() {
        let l = progress_line(40, 200, 38, 2, Duration::from_secs(150));
        assert_eq!(
            l,
            "progress: 40/200 images (38 written, 2 failed), 912 img/h, elapsed 2m 30s, ETA 10m 00s"
        );
        let l = progress_line(12, 20, 2, 0, Duration::from_secs(10));
        assert!(
            l.contains("(2 written, 10 already complete, 0 failed)"),
            "{l}"
        );
        assert!(l.ends_with("ETA 40s"), "{l}");
        assert!(progress_line(0, 5, 0, 0, Duration::ZERO).ends_with("ETA unknown"));
        assert!(progress_line(5, 5, 5, 0, Duration::from_secs(7200)).contains("elapsed 2h 00m"));
    }

    #[test]
    fn batch_lines_come_every_few_images_and_at_the_end() {
        let b = BatchProgress::new(1000);
        assert_eq!(b.every_images, 50);
        assert_eq!(BatchProgress::new(3).every_images, 3);
        assert_eq!(BatchProgress::new(100).every_images, 10);
    }
}
