//! What a run of `generate` or `render` prints: the progress bar, the progress lines of a batch
//! log ([`BatchProgress`]) and the summary with the time split ([`print_summary`]).

use std::io::IsTerminal;
use std::path::Path;
use std::time::Duration;

use clevrtex_render::pool::RunReport;
use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};

/// The progress lines of a batch log (stderr not a terminal): `progress: 40/200 images (38
/// written, 2 failed), 912 img/h, ETA 10m 31s`, at most every [`Self::EVERY_IMAGES`]
/// images or 5% of the run (whichever is more), and every [`Self::EVERY`] while nothing ends.
pub(crate) struct BatchProgress {
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

    pub(crate) fn new(total: u64) -> Self {
        BatchProgress {
            total,
            every_images: (total / 20).max(Self::EVERY_IMAGES.min(total.max(1))),
            last: std::sync::Mutex::new((0, Duration::ZERO)),
        }
    }

    /// After an image ended (`position` counted, skipped ones included): a line when enough
    /// images ended since the last one, or at the last image.
    pub(crate) fn event(&self, position: u64, done: u64, failed: u64, elapsed: Duration) {
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
    pub(crate) fn tick(&self, position: u64, done: u64, failed: u64, elapsed: Duration) {
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

pub(crate) fn progress_bar(total: u64) -> ProgressBar {
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

pub(crate) fn print_summary(r: &RunReport, out: &Path, ledger: &Path) {
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
        "  visibility pass  {:>8.1} s  (all {} passes incl. rejected: build {:.1} s, cycles {:.1} s; {} layout(s) accepted from the geometry without one)",
        r.visibility_s, r.visibility_passes, r.visibility_build_s, r.visibility_render_s, r.preaccepts
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
