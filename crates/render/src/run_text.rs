//! What a run of `generate` or `render` prints, as text (the command prints it): the progress
//! lines of a batch log ([`BatchProgress`]), durations ([`format_duration`]), a pool event's
//! line ([`event_line`]) and the summary with the time split ([`summary`]).

use std::fmt::Write;
use std::path::Path;
use std::time::Duration;

use crate::pool::{PoolEvent, RunReport};

/// The progress lines of a batch log, for the command to print (stderr not a terminal): `progress: 40/200 images (38
/// written, 2 failed), 912 img/h, ETA 10m 31s`, at most every [`Self::EVERY_IMAGES`]
/// images or 5% of the run (whichever is more), and every [`Self::EVERY`] while nothing ends.
pub struct BatchProgress {
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

    /// The lines of a run of `total` images.
    pub fn new(total: u64) -> Self {
        BatchProgress {
            total,
            every_images: (total / 20).max(Self::EVERY_IMAGES.min(total.max(1))),
            last: std::sync::Mutex::new((0, Duration::ZERO)),
        }
    }

    /// After an image ended (`position` counted, skipped ones included): a line when enough
    /// images ended since the last one, or at the last image.
    pub fn event(
        &self,
        position: u64,
        done: u64,
        failed: u64,
        elapsed: Duration,
    ) -> Option<String> {
        let mut last = self.last.lock().unwrap_or_else(|e| e.into_inner());
        if position >= last.0 + self.every_images || (position == self.total && last.0 < position) {
            *last = (position, elapsed);
            return Some(progress_line(position, self.total, done, failed, elapsed));
        }
        None
    }

    /// Every so often: a line when [`Self::EVERY`] passed since the last one.
    pub fn tick(&self, position: u64, done: u64, failed: u64, elapsed: Duration) -> Option<String> {
        let mut last = self.last.lock().unwrap_or_else(|e| e.into_inner());
        if elapsed >= last.1 + Self::EVERY && position < self.total {
            *last = (position, elapsed);
            return Some(progress_line(position, self.total, done, failed, elapsed));
        }
        None
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
pub fn format_duration(secs: f64) -> String {
    let s = secs.max(0.0).round() as u64;
    match s {
        0..=59 => format!("{s}s"),
        60..=3599 => format!("{}m {:02}s", s / 60, s % 60),
        _ => format!("{}h {:02}m", s / 3600, s % 3600 / 60),
    }
}

/// The line a pool event shows (warnings, notes, errors), if any; `ledger` is where failures
/// are recorded.
pub fn event_line(ev: &PoolEvent, ledger: &Path) -> Option<String> {
    match ev {
        PoolEvent::WorkerRestarted { error } => {
            Some(format!("warning: restarting a Blender worker: {error}"))
        }
        PoolEvent::Done { sample } => {
            // Only fixed scene files (`render`) can get here with a hidden object:
            // `generate` resamples such layouts.
            let hidden: Vec<String> = (1..)
                .zip(&sample.objects)
                .filter(|(_, o)| o.pixels == 0)
                .map(|(i, _)| i.to_string())
                .collect();
            (!hidden.is_empty()).then(|| format!(
                "warning: object(s) {} of `{}` are hidden (not in the mask)\nhint: `clevrtex render` cannot resample fixed scene files; use `clevrtex generate` for layouts with every object visible",
                hidden.join(", "),
                sample.metadata.display()
            ))
        }
        PoolEvent::WorkerRecycled { rss, images, why } => {
            let mem = rss
                .map(|r| format!(", {} MiB resident", r >> 20))
                .unwrap_or_default();
            Some(format!(
                "note: a Blender worker made {images} image(s){mem} and was recycled ({}); the next image starts a fresh one",
                if *why == "memory" {
                    "past `--max-worker-memory`"
                } else {
                    "`--recycle-after`"
                }
            ))
        }
        PoolEvent::Failed { index, error } => Some(format!(
            "error: image {index} failed (recorded in `{}`): {error}",
            ledger.display()
        )),
        _ => None,
    }
}

/// The bridge's phases (every request, rejects included), CPU and wall seconds; nothing from
/// a bridge that does not report them.
fn phases_line(out: &mut String, p: &crate::BridgePhases) {
    if p.cpu_s() <= 0.0 {
        return;
    }
    let parts: Vec<String> = p
        .named()
        .iter()
        .filter(|(_, t)| t.cpu_s > 0.0 || t.wall_s > 0.0)
        .map(|(name, t)| format!("{name} {:.1}/{:.1}", t.cpu_s, t.wall_s))
        .collect();
    let _ = writeln!(
        out,
        "  bridge phases    {:>8.1} CPU-s  (CPU/wall s: {})",
        p.cpu_s(),
        parts.join(", ")
    );
}

/// The summary of a run (stdout's lines), failures recorded in `ledger`, output in `out_dir`;
/// with a warning for stderr when lines of the ledger were unreadable.
pub fn summary(r: &RunReport, out_dir: &Path, ledger: &Path) -> (String, Option<String>) {
    let mut out = String::new();
    let _ = writeln!(
                out,
        "rendered {} images ({} already complete, {} failed) in {:.1} s with {} worker(s) x {} thread(s)",
        r.done,
        r.skipped,
        r.failed.len(),
        r.wall_s,
        r.workers,
        r.threads
    );
    if r.done > 0 {
        let _ = writeln!(
            out,
            "  {:.1} s per image, {:.0} images/hour",
            r.wall_s / r.done as f64,
            r.done as f64 / r.wall_s.max(1e-9) * 3600.0
        );
    }
    let _ = writeln!(out, "time split (summed over workers):");
    let _ = writeln!(
        out,
        "  blender start    {:>8.1} s  ({} start(s))",
        r.blender_start_s, r.worker_starts
    );
    let _ = writeln!(out, "  scene build      {:>8.1} s", r.build_s);
    let _ = writeln!(
                out,
        "  visibility pass  {:>8.1} s  (all {} passes incl. rejected: build {:.1} s, cycles {:.1} s; {} layout(s) accepted from the geometry without one)",
        r.visibility_s, r.visibility_passes, r.visibility_build_s, r.visibility_render_s, r.preaccepts
    );
    let _ = writeln!(out, "  render (cycles)  {:>8.1} s", r.render_s);
    let _ = writeln!(
        out,
        "  bridge other     {:>8.1} s  (writing EXR/PNG in Blender, protocol)",
        (r.final_request_s - r.render_s - r.build_s).max(0.0)
    );
    let _ = writeln!(out, "  post-processing  {:>8.1} s", r.post_s);
    phases_line(&mut out, &r.phases);
    let _ = writeln!(
                out,
        "  rejects          {:>8.1} s  ({} rejected layout(s), {} from the geometry without a visibility pass; checked after the full render they would have cost ~{:.1} s)",
        r.reject_s,
        r.rejects,
        r.prerejects,
        r.rejects_cost_if_checked_after()
    );
    if r.peak_rss > 0 {
        let _ = writeln!(
            out,
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
        let _ = writeln!(
            out,
            "  overhead: wall x workers / cycles render = {ratio:.3}"
        );
    }
    let _ = writeln!(out, "output: {}", out_dir.display());
    let warning = (r.ledger_unreadable > 0).then(|| {
        format!(
            "warning: dropped {} unreadable line(s) of the failure ledger `{}` (left by a run killed while writing it); rerun without `--overwrite` to find what is still missing",
            r.ledger_unreadable,
            ledger.display()
        )
    });
    if !r.failed.is_empty() {
        let _ = writeln!(
            out,
            "failures recorded in `{}`; rerun the same command to retry them",
            ledger.display()
        );
    }
    (out, warning)
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::time::Duration;

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
