//! Rust errors as the Python exceptions the package raises: `ValueError` for what was given,
//! `OSError` of its errno for a file that cannot be opened.

use clevrtex_eval::EvalError;
use pyo3::exceptions::{PyOSError, PyValueError};
use pyo3::PyErr;

pub(crate) fn value_error(e: impl std::fmt::Display) -> PyErr {
    PyValueError::new_err(e.to_string())
}

pub(crate) fn eval_error(e: EvalError) -> PyErr {
    match e {
        EvalError::Io { .. } => PyOSError::new_err(e.to_string()),
        other => value_error(other),
    }
}

/// Why a file of the dataset was not read, as the Python exception of its kind: `OSError` of
/// its errno (`FileNotFoundError`, `PermissionError`, ...) when it cannot be opened, else
/// `ValueError`; the message names the file.
pub(crate) fn read_error(path: &str, e: clevrtex_dataset::dataset::ReadError) -> PyErr {
    use clevrtex_dataset::dataset::ReadError;
    match e {
        // OSError(errno, message, filename) is the subclass of its errno.
        ReadError::Io(e) => PyOSError::new_err((
            e.raw_os_error().unwrap_or(0),
            format!("`{path}` cannot be read: {e}"),
            path.to_string(),
        )),
        other => value_error(format!(
            "`{path}` {}; not read",
            other.to_string().trim_end_matches("; skipped")
        )),
    }
}
