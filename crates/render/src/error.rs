//! Errors of the render crate: each names the offending program, file or scene and ends with
//! a `hint:` line saying what to do next.

use std::path::PathBuf;
use std::process::ExitStatus;
use std::time::Duration;

use clevrtex_dataset::error::IoFailure;
use clevrtex_scene::text::{printable, printable_lines};

/// Smallest image (in pixels) at which every object of a default layout can cover a pixel:
/// below it, layouts are rejected because of the image's size, not of the configuration.
const MIN_VISIBLE_IMAGE_PX: u64 = 32 * 24;

fn rejects_hint(width: u32, height: u32) -> String {
    if u64::from(width) * u64::from(height) < MIN_VISIBLE_IMAGE_PX {
        format!("the image ({width}x{height}) is too small for every object to cover a pixel; use a larger `--width`/`--height` (at least 32x24)")
    } else {
        "the configuration places objects where they cannot be seen; use fewer or larger objects"
            .to_string()
    }
}

/// The last lines a Blender process printed, kept for error reports.
#[derive(Debug, Clone, Default)]
pub struct Tails {
    /// Last lines of stdout (Blender's own chatter; protocol replies are not kept here).
    pub stdout: Vec<String>,
    /// Last lines of stderr.
    pub stderr: Vec<String>,
}

impl std::fmt::Display for Tails {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        for (label, lines) in [("stdout", &self.stdout), ("stderr", &self.stderr)] {
            if lines.is_empty() {
                writeln!(f, "--- {label}: (empty)")?;
            } else {
                writeln!(f, "--- {label} (last {} lines)", lines.len())?;
                for line in lines {
                    writeln!(f, "{}", printable(line))?;
                }
            }
        }
        Ok(())
    }
}

/// Anything that can go wrong while driving Blender or writing a sample.
#[derive(Debug, thiserror::Error)]
pub enum RenderError {
    /// No Blender executable was found.
    #[error("blender not found{}\nhint: install it with `apt-get install blender`, or pass its path with `--blender PATH` (or set `CLEVRTEX_BLENDER`)", .tried.as_ref().map(|p| format!(" at `{}`", p.display())).unwrap_or_default())]
    BlenderNotFound {
        /// The explicit path that did not exist, if one was given.
        tried: Option<PathBuf>,
    },
    /// The Blender given is a folder, not a program.
    #[error("`{}` is a folder, not a Blender executable\nhint: pass the program itself, e.g. `--blender {}` (or a Python with `bpy`, e.g. `.venv-bpy/bin/python`)", .path.display(), .path.join("blender").display())]
    BlenderIsFolder {
        /// The folder given.
        path: PathBuf,
    },
    /// The Blender process could not be started.
    #[error("could not start `{}`: {cause}\nhint: check that the file is an executable Blender (`{} --version`), or pass another with `--blender PATH`", .program.display(), .program.display())]
    Spawn {
        /// The program.
        program: PathBuf,
        /// The OS error. Not named `source`: the message already shows it, and as the error's
        /// source it would be printed a second time, after the `hint:` line.
        cause: std::io::Error,
    },
    /// The worker did not answer within the time limit; it was killed.
    #[error("blender worker `{}` timed out after {:.1} s while {doing}; it was killed\n{tails}hint: {}", .program.display(), .after.as_secs_f64(), timeout_hint(.doing))]
    Timeout {
        /// The program.
        program: PathBuf,
        /// What the worker was doing (e.g. `rendering scene `x.json` (final)`).
        doing: String,
        /// How long we waited.
        after: Duration,
        /// Output tails.
        tails: Box<Tails>,
    },
    /// The worker exited while we waited for it.
    #[error("blender worker `{}` exited ({}) while {doing}\n{tails}hint: the stderr tail above says why; run `clevrtex doctor` to check the Blender install", .program.display(), status_text(.status))]
    Exited {
        /// The program.
        program: PathBuf,
        /// What the worker was doing.
        doing: String,
        /// Its exit status, if it could be read.
        status: Option<ExitStatus>,
        /// Output tails.
        tails: Box<Tails>,
    },
    /// The worker printed a reply line that is not valid protocol.
    #[error("blender worker `{}` sent a malformed reply while {doing}: `{}` ({})\n{tails}hint: a reply line was cut or garbled (the worker crashed mid-write, or something else in Blender wrote to the reply stream); the request is retried with a fresh worker; if it keeps happening, run `clevrtex doctor` and report it with the output above", .program.display(), printable(.line), printable(.problem))]
    Protocol {
        /// The program.
        program: PathBuf,
        /// What the worker was doing.
        doing: String,
        /// The offending line (truncated).
        line: String,
        /// What is wrong with it.
        problem: String,
        /// Output tails.
        tails: Box<Tails>,
    },
    /// The bridge reported an error for one request (the worker stays usable).
    #[error("the blender bridge failed while {doing}: {}\n{}hint: check the scene file; if it came from `clevrtex sample`, this is a bug: please report it with the traceback", printable(.message), printable_lines(.traceback))]
    Bridge {
        /// What the worker was doing.
        doing: String,
        /// The bridge's message.
        message: String,
        /// Python traceback (may be empty).
        traceback: String,
    },
    /// No worker could ever be started in this run (so every scene would fail the same way).
    #[error(transparent)]
    WorkerStart(Box<RenderError>),
    /// The run was interrupted (Ctrl-C).
    #[error("interrupted")]
    Interrupted,
    /// The output folder holds something this run will not write through (a link leading out
    /// of `--out` where the layout has a folder, a FIFO, ...): the message names it, with a hint.
    #[error("{0}")]
    Refused(String),
    /// `--device` asks for GPUs the machine does not have (the message of
    /// [`crate::device::plan`], with its hint).
    #[error("{0}")]
    DevicePlan(String),
    /// Reading or writing a file failed (the dataset writers' error, with the same text).
    #[error(transparent)]
    Io(#[from] IoFailure),
    /// An image failed and its failure could not be written to the failure ledger (e.g. the
    /// disk is full): the run stops, since it could not say what is missing.
    #[error("image {index} failed and its failure could not be recorded in the ledger `{}`: {cause}\nthe image's error: {failure}\nhint: free disk space (or make the folder writable) and rerun the same command: finished samples are kept and the ledger on disk is unchanged", .path.display())]
    LedgerWrite {
        /// The ledger.
        path: PathBuf,
        /// The image.
        index: u64,
        /// Why the image failed.
        failure: String,
        /// Why the ledger could not be written.
        cause: std::io::Error,
    },
    /// `blender --version` did not finish in time.
    #[error("`{} --version` did not answer within {} s; it was killed\nhint: this program is not a working Blender (or hangs at start-up); pass another with `--blender PATH`, or check it by running `{} -b --version`", .program.display(), .waited.as_secs(), .program.display())]
    VersionTimeout {
        /// The program.
        program: PathBuf,
        /// How long we waited.
        waited: std::time::Duration,
    },
    /// A file Blender wrote could not be decoded or lacks what we asked for.
    #[error("bad render output `{}`: {problem}\nhint: Blender wrote something other than what was asked for (a full disk under `$TMPDIR`, or a Blender version clevrtex does not support); run `clevrtex doctor`", .path.display())]
    BadOutput {
        /// The file.
        path: PathBuf,
        /// What is wrong.
        problem: String,
    },
    /// A scene file could not be read or is invalid.
    #[error("bad scene file `{}`: {problem}\nhint: regenerate it with `clevrtex sample`", .path.display())]
    BadScene {
        /// The scene file.
        path: PathBuf,
        /// What is wrong.
        problem: String,
    },
    /// The scene sampler could not produce a scene.
    #[error("cannot sample scene {index} (attempt {attempt}): {message}")]
    Sample {
        /// Image index.
        index: u64,
        /// Attempt number.
        attempt: u32,
        /// Why.
        message: String,
    },
    /// Every attempt produced a layout with a (nearly) hidden object.
    #[error("scene {index}: {attempts} layouts in a row had an object with at most {threshold} visible pixels at {width}x{height}\nhint: {}", rejects_hint(*.width, *.height))]
    TooManyRejects {
        /// Image index.
        index: u64,
        /// Attempts made.
        attempts: u32,
        /// The pixel threshold.
        threshold: u64,
        /// Image width in pixels.
        width: u32,
        /// Image height in pixels.
        height: u32,
    },
}

impl RenderError {
    /// Whether restarting the worker and trying again could help (crash, hang, garbage).
    pub fn is_worker_failure(&self) -> bool {
        matches!(
            self,
            RenderError::Timeout { .. } | RenderError::Exited { .. } | RenderError::Protocol { .. }
        )
    }

    /// Shorthand for an I/O error with a hint.
    pub fn io(
        what: &'static str,
        path: impl Into<PathBuf>,
        source: std::io::Error,
        hint: impl Into<String>,
    ) -> RenderError {
        RenderError::Io(IoFailure::new(what, path, source, hint))
    }

    /// I/O error writing an output file; the hint covers full disks and permissions.
    pub fn write(path: impl Into<PathBuf>, source: std::io::Error) -> RenderError {
        RenderError::Io(IoFailure::write(path, source))
    }
}

/// What to raise when a worker timed out while `doing` something.
fn timeout_hint(doing: &str) -> &'static str {
    if doing == STARTING_UP {
        "raise `--startup-timeout` (seconds) if Blender is just slow to start (a busy machine or a network file system), or run `clevrtex doctor`"
    } else {
        "raise `--timeout` (seconds) if renders are just slow, or lower `--samples`"
    }
}

/// What a worker is doing while it starts (in [`RenderError`] messages).
pub(crate) const STARTING_UP: &str = "starting up";

fn status_text(status: &Option<ExitStatus>) -> String {
    match status {
        Some(s) => s.to_string(),
        None => "status unknown".to_string(),
    }
}

/// Result alias of this crate.
pub type Result<T, E = RenderError> = std::result::Result<T, E>;

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn io_errors_show_their_cause_once_before_the_hint() {
        let e = RenderError::write("/x/a.png", std::io::Error::other("no space left"));
        // A source would be printed again after the hint by `{:#}` reporters (anyhow).
        assert!(std::error::Error::source(&e).is_none());
        let text = e.to_string();
        assert!(text.contains("`/x/a.png`: no space left\nhint: "), "{text}");
        let spawn = RenderError::Spawn {
            program: "/bin/b".into(),
            cause: std::io::Error::other("denied"),
        };
        assert!(std::error::Error::source(&spawn).is_none());
    }
}
