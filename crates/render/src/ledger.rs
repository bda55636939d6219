//! The failure ledger: one JSON line per image that failed (`index`, `stem`, `variant`,
//! `error`, `time_unix`), at most one per stem (a later failure of the same image replaces the
//! earlier one).
//!
//! The file is never appended to: every change rewrites it through a temporary file and a
//! rename, so a kill or a full disk leaves the previous ledger whole (never a 0-byte or
//! half-written one). Lines that cannot be read (an older tool killed mid-append) are dropped
//! at the next rewrite and counted, so the run can say so.

use std::collections::{BTreeMap, BTreeSet};
use std::io::Write;
use std::path::{Path, PathBuf};

use crate::error::{RenderError, Result};
use crate::job::Job;
use crate::output;

/// The ledger of one run, as loaded at its start.
#[derive(Debug)]
pub(crate) struct Ledger {
    path: PathBuf,
    /// Entries by stem, each one JSON line (without the newline).
    entries: BTreeMap<String, String>,
    /// Lines of the file on disk that could not be read.
    unreadable: usize,
    /// Whether `entries` differ from the file.
    dirty: bool,
}

impl Ledger {
    /// Load the ledger at `path` (empty when there is none). A missing or unreadable file is
    /// an empty ledger; its unreadable lines are counted.
    pub(crate) fn open(path: &Path) -> Ledger {
        let mut entries = BTreeMap::new();
        let mut unreadable = 0;
        if let Ok(text) = std::fs::read_to_string(path) {
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
        }
        Ledger {
            path: path.to_path_buf(),
            entries,
            unreadable,
            dirty: false,
        }
    }

    /// The ledger's file.
    pub(crate) fn path(&self) -> &Path {
        &self.path
    }

    /// Lines of the file on disk that could not be read (dropped at the next rewrite).
    pub(crate) fn unreadable(&self) -> usize {
        self.unreadable
    }

    /// Record the failure of `job` (replacing an earlier one of the same stem) and rewrite the
    /// file. On error the file on disk is unchanged.
    pub(crate) fn record(&mut self, job: &Job, err: &RenderError) -> std::io::Result<()> {
        let line = serde_json::json!({
            "index": job.index,
            "stem": job.stem,
            "variant": job.variant,
            "error": err.to_string(),
            "time_unix": std::time::SystemTime::now()
                .duration_since(std::time::UNIX_EPOCH)
                .map(|d| d.as_secs())
                .unwrap_or(0),
        });
        let old = self.entries.insert(job.stem.clone(), line.to_string());
        let result = self.write();
        if result.is_err() {
            // Keep memory and disk in agreement: the failure was not recorded.
            match old {
                Some(old) => self.entries.insert(job.stem.clone(), old),
                None => self.entries.remove(&job.stem),
            };
        }
        result
    }

    /// After a finished run: drop the entries of `ran` (the run's stems) that did not fail
    /// now (a rerun made them), so the ledger lists only what is still missing; remove the file
    /// when nothing is. Also rewrites a file that had unreadable lines.
    pub(crate) fn prune(
        &mut self,
        ran: &BTreeSet<String>,
        failed: &BTreeSet<String>,
    ) -> Result<()> {
        let before = self.entries.len();
        self.entries
            .retain(|stem, _| !ran.contains(stem) || failed.contains(stem));
        if self.entries.len() != before || self.unreadable > 0 {
            self.dirty = true;
        }
        if !self.dirty {
            return Ok(());
        }
        if self.entries.is_empty() {
            return match std::fs::remove_file(&self.path) {
                Err(e) if e.kind() != std::io::ErrorKind::NotFound => {
                    Err(RenderError::write(&self.path, e))
                }
                _ => Ok(()),
            };
        }
        self.write().map_err(|e| RenderError::write(&self.path, e))
    }

    /// Write every entry to a temporary file, flush it to disk and rename it over the ledger.
    fn write(&mut self) -> std::io::Result<()> {
        if let Some(parent) = self.path.parent() {
            std::fs::create_dir_all(parent)?;
        }
        let tmp = self
            .path
            .with_extension(format!("jsonl{}", output::TMP_SUFFIX));
        let body: String = self.entries.values().map(|l| format!("{l}\n")).collect();
        let written = std::fs::File::create(&tmp).and_then(|mut f| {
            f.write_all(body.as_bytes())?;
            f.sync_all()
        });
        let renamed = written.and_then(|()| std::fs::rename(&tmp, &self.path));
        if renamed.is_err() {
            let _ = std::fs::remove_file(&tmp);
        } else {
            self.dirty = false;
            self.unreadable = 0;
        }
        renamed
    }
}
