//! Errors of writing a dataset's files (a manifest, its hashes) and of refusing a folder:
//! each names the file and ends with a `hint:` line. `clevrtex-render` turns them into its
//! `RenderError` with the same text.

use std::path::PathBuf;

/// Reading or writing a file of a dataset failed, or a folder is refused.
#[derive(Debug, thiserror::Error)]
pub enum Error {
    /// The output folder holds something this run will not write into (a manifest of a run
    /// with other settings, ...): the message names it, with a hint.
    #[error("{0}")]
    Refused(String),
    /// Reading or writing a file failed.
    #[error(transparent)]
    Io(IoFailure),
}

/// Reading or writing a file failed: what we were doing, the file, the OS error and what to
/// do about it. The one I/O error of the writers of this crate and of `clevrtex-render`.
#[derive(Debug, thiserror::Error)]
#[error("{what} `{}`: {cause}\nhint: {hint}", .path.display())]
pub struct IoFailure {
    /// What we were doing, e.g. `cannot write`.
    pub what: &'static str,
    /// The file.
    pub path: PathBuf,
    /// The OS error. Not named `source`: the message already shows it, and as the error's
    /// source it would be printed a second time, after the `hint:` line.
    pub cause: std::io::Error,
    /// What to do about it.
    pub hint: String,
}

impl IoFailure {
    /// An I/O failure with a hint.
    pub fn new(
        what: &'static str,
        path: impl Into<PathBuf>,
        cause: std::io::Error,
        hint: impl Into<String>,
    ) -> IoFailure {
        IoFailure {
            what,
            path: path.into(),
            cause,
            hint: hint.into(),
        }
    }

    /// Writing an output file failed; the hint covers full disks and permissions.
    pub fn write(path: impl Into<PathBuf>, cause: std::io::Error) -> IoFailure {
        IoFailure::new(
            "cannot write",
            path,
            cause,
            "check that the output folder is writable and the disk is not full; finished samples were kept and the run can be resumed",
        )
    }
}

impl Error {
    /// Shorthand for an I/O error with a hint.
    pub fn io(
        what: &'static str,
        path: impl Into<PathBuf>,
        source: std::io::Error,
        hint: impl Into<String>,
    ) -> Error {
        Error::Io(IoFailure::new(what, path, source, hint))
    }

    /// I/O error writing an output file; the hint covers full disks and permissions.
    pub fn write(path: impl Into<PathBuf>, source: std::io::Error) -> Error {
        Error::Io(IoFailure::write(path, source))
    }
}

/// Result alias of this crate's writers.
pub type Result<T, E = Error> = std::result::Result<T, E>;
