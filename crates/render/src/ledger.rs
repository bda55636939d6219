//! The failure ledger: one JSON line per image that failed (`index`, `stem`, `variant`,
//! `error`, `time_unix`), at most one per stem (a later failure of the same image replaces the
//! earlier one).
//!
//! Several runs may share one ledger: the shards of a SLURM array or a Kubernetes Indexed Job
//! write into one variant folder. Every change therefore happens under an exclusive lock on
//! `.failures.jsonl.lock` beside it: read the file as it is now, change it, write it through a
//! temporary file and a rename. A kill or a full disk leaves the previous ledger whole (never a
//! 0-byte or half-written one), and no run loses another's entries. Lines that cannot be read
//! (an older tool killed mid-append) are dropped at the next rewrite and counted, so the run
//! can say so.

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};

use clevrtex_dataset::dataset;

use crate::error::{RenderError, Result};

/// A run's handle on its ledger file.
#[derive(Debug)]
pub(crate) struct Ledger {
    path: PathBuf,
    /// Unreadable lines of the file when the run started.
    unreadable: usize,
}

/// Entries by stem, each one JSON line (without the newline), and the unreadable lines. The
/// ledger lives in a folder that may be a dataset handed over: only a regular file is read
/// (not through a link, which could lead anywhere, nor a FIFO, which would block), with the
/// dataset reader's cap; anything else in its place is refused, naming it.
fn load(path: &Path) -> std::result::Result<(BTreeMap<String, String>, usize), String> {
    let mut entries = BTreeMap::new();
    let mut unreadable = 0;
    let refuse = |what: &str| {
        format!(
            "the failure ledger `{}` {what}; it is not followed or read, and not changed\nhint: remove it (or put the ledger file itself in its place) and run again",
            path.display()
        )
    };
    match std::fs::symlink_metadata(path) {
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok((entries, 0)),
        Err(e) => return Err(format!("cannot read `{}`: {e}", path.display())),
        Ok(m) if m.file_type().is_symlink() => return Err(refuse("is a symbolic link")),
        Ok(m) if !m.is_file() => {
            return Err(refuse(
                "is not a regular file (a FIFO, socket, device or folder)",
            ))
        }
        Ok(_) => {}
    }
    let bytes = match dataset::read_regular(path, dataset::MAX_LEDGER_BYTES) {
        Ok(b) => b,
        Err(dataset::ReadError::Io(e)) if e.kind() == std::io::ErrorKind::NotFound => {
            return Ok((entries, 0))
        }
        Err(e) => return Err(refuse(&e.to_string())),
    };
    let text = String::from_utf8_lossy(&bytes);
    for line in text.lines().filter(|l| !l.trim().is_empty()) {
        let stem = serde_json::from_str::<serde_json::Value>(line)
            .ok()
            .and_then(|v| v["stem"].as_str().map(str::to_string));
        match stem {
            // Older tools appended: the last line of a stem is its latest failure.
            Some(stem) => {
                entries.insert(stem, line.to_string());
            }
            None => unreadable += 1,
        }
    }
    Ok((entries, unreadable))
}

impl Ledger {
    /// The ledger at `path` (it need not exist), counting its unreadable lines. `Err` when
    /// something other than a regular file is in its place (a link, a FIFO).
    pub(crate) fn open(path: &Path) -> Result<Ledger> {
        // Its lock file is judged when it is opened ([`clevrtex_dataset::run_lock::open_lock_file`], at
        // the first change): a link or FIFO there is refused, naming it; a folder there fails
        // the write as a full disk would.
        Ok(Ledger {
            path: path.to_path_buf(),
            unreadable: load(path).map_err(RenderError::Refused)?.1,
        })
    }

    /// The lock file beside the ledger, `.<name>.lock`.
    fn lock_path(&self) -> PathBuf {
        let name = self.path.file_name().unwrap_or_default().to_string_lossy();
        self.path
            .parent()
            .unwrap_or(Path::new("."))
            .join(format!(".{name}.lock"))
    }

    /// The ledger's file.
    pub(crate) fn path(&self) -> &Path {
        &self.path
    }

    /// Lines of the file that could not be read when the run started (dropped at the next
    /// rewrite).
    pub(crate) fn unreadable(&self) -> usize {
        self.unreadable
    }

    /// Under the lock: load the file, let `change` edit the entries (it says whether it
    /// changed anything), and write the result back (or remove the file when it is empty).
    fn update(
        &self,
        change: impl FnOnce(&mut BTreeMap<String, String>) -> bool,
    ) -> std::io::Result<()> {
        let dir = self.path.parent().unwrap_or(Path::new("."));
        std::fs::create_dir_all(dir)?;
        let lock = clevrtex_dataset::run_lock::open_lock_file(&self.lock_path())
            .map_err(std::io::Error::other)?;
        lock.lock()?;
        let (mut entries, unreadable) = load(&self.path).map_err(std::io::Error::other)?;
        if !change(&mut entries) && unreadable == 0 {
            return Ok(());
        }
        if entries.is_empty() {
            return match std::fs::remove_file(&self.path) {
                Err(e) if e.kind() != std::io::ErrorKind::NotFound => Err(e),
                _ => Ok(()),
            };
        }
        let body: String = entries.values().map(|l| format!("{l}\n")).collect();
        clevrtex_dataset::atomic::write(&self.path, body.as_bytes())
    }

    /// Record the failure `err` of image `index` (`stem`, of `variant`), replacing an earlier
    /// one of the same stem. On error the file on disk is unchanged.
    pub(crate) fn record(
        &self,
        index: u64,
        stem: &str,
        variant: &str,
        err: &RenderError,
    ) -> std::io::Result<()> {
        let line = serde_json::json!({
            "index": index,
            "stem": stem,
            "variant": variant,
            "error": err.to_string(),
            "time_unix": std::time::SystemTime::now()
                .duration_since(std::time::UNIX_EPOCH)
                .map(|d| d.as_secs())
                .unwrap_or(0),
        });
        self.update(|entries| {
            entries.insert(stem.to_string(), line.to_string());
            true
        })
    }

    /// After a finished run: drop the entries of `ran` (the run's stems) that did not fail
    /// now (a rerun made them), so the ledger lists only what is still missing; the file goes
    /// when nothing is. Entries of other runs (other shards) are kept.
    pub(crate) fn prune(
        &self,
        ran: &dyn Fn(&str) -> bool,
        failed: &BTreeSet<String>,
    ) -> Result<()> {
        if std::fs::symlink_metadata(&self.path).is_err() {
            return Ok(());
        }
        self.update(|entries| {
            let before = entries.len();
            entries.retain(|stem, _| !ran(stem) || failed.contains(stem));
            entries.len() != before
        })
        .map_err(|e| match e.kind() {
            // A refusal of [`load`] or [`clevrtex_dataset::run_lock::open_lock_file`], with its hint.
            std::io::ErrorKind::Other => RenderError::Refused(format!(
                "cannot update the failure ledger `{}`: {e}",
                self.path.display()
            )),
            _ => RenderError::write(&self.path, e),
        })
    }
}
