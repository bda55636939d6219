//! The failure ledger: one JSON line per job that failed (`index`, `stem`, `variant`,
//! `error`, `time_unix`), appended while a run goes and pruned when it ends.

use std::collections::BTreeSet;
use std::io::Write;
use std::path::Path;

use crate::error::{RenderError, Result};
use crate::job::Job;
use crate::output;

/// Append the failure of `job` to the ledger at `ledger` (its folder created if missing).
/// Callers serialise appends.
pub(crate) fn record(ledger: &Path, job: &Job, err: &RenderError) -> Result<()> {
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
    if let Some(parent) = ledger.parent() {
        std::fs::create_dir_all(parent).map_err(|e| RenderError::write(parent, e))?;
    }
    let mut f = std::fs::OpenOptions::new()
        .create(true)
        .append(true)
        .open(ledger)
        .map_err(|e| RenderError::write(ledger, e))?;
    writeln!(f, "{line}").map_err(|e| RenderError::write(ledger, e))
}

/// After a finished run, drop the ledger entries of this run's samples that are complete
/// now (a rerun retried them), so the ledger lists only what is still missing; remove it
/// when nothing is.
pub(crate) fn prune(
    ledger: &Path,
    stems: &BTreeSet<String>,
    failed: &[(u64, String)],
) -> Result<()> {
    let Ok(text) = std::fs::read_to_string(ledger) else {
        return Ok(());
    };
    let failed: BTreeSet<u64> = failed.iter().map(|f| f.0).collect();
    let keep: Vec<&str> = text
        .lines()
        .filter(|line| {
            let Ok(v) = serde_json::from_str::<serde_json::Value>(line) else {
                return true;
            };
            let ran = v["stem"].as_str().is_some_and(|s| stems.contains(s));
            let failed_now = v["index"].as_u64().is_some_and(|i| failed.contains(&i));
            !ran || failed_now
        })
        .collect();
    if keep.len() == text.lines().count() {
        return Ok(());
    }
    if keep.is_empty() {
        return std::fs::remove_file(ledger).map_err(|e| RenderError::write(ledger, e));
    }
    let tmp = ledger.with_extension(format!("jsonl{}", output::TMP_SUFFIX));
    let body: String = keep.iter().map(|l| format!("{l}\n")).collect();
    std::fs::write(&tmp, body).map_err(|e| RenderError::write(&tmp, e))?;
    std::fs::rename(&tmp, ledger).map_err(|e| RenderError::write(ledger, e))
}
