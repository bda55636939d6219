//! Private temporary folders (`clevrtex-bridge-*`, `clevrtex-work-*`, `clevrtex-blender-*` in
//! `$TMPDIR`) that are cleaned up even after a `kill -9`.
//!
//! Each folder holds an `owner` file: the pid and the start time (clock ticks since boot,
//! `/proc/<pid>/stat` field 22) of the process that made it. A dropped folder is removed at
//! once; folders whose owner is gone (killed, so its destructors never ran) are removed by the
//! next run, in [`remove_stale`], which every run calls when it makes its bridge folder. The
//! start time tells a dead owner from a new process that got the same pid.

use std::path::Path;

/// Prefixes of our folders in `$TMPDIR`.
const PREFIXES: [&str; 3] = ["clevrtex-bridge-", "clevrtex-work-", "clevrtex-blender-"];
/// The ownership file in each folder.
const OWNER: &str = "owner";

use clevrtex_dataset::atomic::start_time;
/// The folder type [`scratch_dir`] returns (removed when dropped).
pub use tempfile::TempDir;

use crate::error::{RenderError, Result};
pub use clevrtex_dataset::atomic::{
    hostname, own_start_time, owner_tag, process_alive, tagged_name_is_stale, HOST_ENV,
};

/// The `owner` line of this process.
fn owner_line() -> String {
    let pid = std::process::id();
    format!("{pid} {}\n", start_time(pid).unwrap_or(0))
}

/// A fresh private folder `$TMPDIR/<prefix>XXXXXX` owned by this process.
pub(crate) fn private_dir(prefix: &str) -> Result<tempfile::TempDir> {
    let make = || -> std::io::Result<tempfile::TempDir> {
        let dir = tempfile::Builder::new().prefix(prefix).tempdir()?;
        std::fs::write(dir.path().join(OWNER), owner_line())?;
        Ok(dir)
    };
    make().map_err(|e| {
        RenderError::io(
            "cannot create a temporary folder in",
            std::env::temp_dir(),
            e,
            "set `TMPDIR` to a writable folder with free space",
        )
    })
}

/// A fresh private scratch folder `$TMPDIR/clevrtex-work-XXXXXX` owned by this process, removed
/// when dropped (or by a later run's [`remove_stale`] after a `kill -9`): where `generate
/// --estimate` renders its calibration images, so that nothing is written into `--out`, and
/// where a run keeps the checked copies of its user materials' files (`render/src/user_materials/copies.rs`).
pub fn scratch_dir() -> Result<tempfile::TempDir> {
    private_dir("clevrtex-work-")
}

/// Whether the folder's owner (per its `owner` file) is still running. Folders without a
/// readable owner file count as alive: they may be being created, or be someone else's.
fn owner_alive(dir: &Path) -> bool {
    let Ok(text) = std::fs::read_to_string(dir.join(OWNER)) else {
        return true;
    };
    let mut it = text.split_whitespace();
    let (Some(Ok(pid)), Some(Ok(start))) = (
        it.next().map(str::parse::<u32>),
        it.next().map(str::parse::<u64>),
    ) else {
        return true;
    };
    start_time(pid).is_some_and(|s| start == 0 || s == start)
}

/// Remove our folders in `$TMPDIR` whose owner process is gone. Returns how many were
/// removed. Never fails: what cannot be removed is left for a later run.
pub fn remove_stale() -> usize {
    remove_stale_in(&std::env::temp_dir())
}

/// [`remove_stale`] in `tmp`. `$TMPDIR` may be shared: only real folders (not links) owned by
/// this user are candidates, so a name that merely looks like ours (another user's folder, a
/// link planted to a folder of ours) is never removed.
fn remove_stale_in(tmp: &Path) -> usize {
    use std::os::unix::fs::MetadataExt;
    let Ok(entries) = std::fs::read_dir(tmp) else {
        return 0;
    };
    let uid = rustix::process::geteuid().as_raw();
    let mut removed = 0;
    for e in entries.flatten() {
        let name = e.file_name().to_string_lossy().into_owned();
        if !PREFIXES.iter().any(|p| name.starts_with(p)) {
            continue;
        }
        let path = e.path();
        let ours = std::fs::symlink_metadata(&path).is_ok_and(|m| m.is_dir() && m.uid() == uid);
        if ours && !owner_alive(&path) && std::fs::remove_dir_all(&path).is_ok() {
            removed += 1;
        }
    }
    removed
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn our_own_folder_is_alive_and_a_dead_owners_is_stale() {
        let mine = private_dir("clevrtex-work-").unwrap();
        assert!(owner_alive(mine.path()));
        assert!(start_time(std::process::id()).is_some_and(|s| s > 0));
        // A process that has exited: its pid no longer matches its start time.
        let mut child = std::process::Command::new("true").spawn().unwrap();
        let pid = child.id();
        child.wait().unwrap();
        let dead = tempfile::Builder::new()
            .prefix("clevrtex-work-")
            .tempdir()
            .unwrap()
            .keep();
        std::fs::write(dead.join(OWNER), format!("{pid} 1\n")).unwrap();
        assert!(!owner_alive(&dead));
        remove_stale();
        assert!(!dead.exists());
        assert!(mine.path().exists(), "a live owner's folder is kept");
    }

    /// Only our user's real folders are swept: before, a link named like our folders (to a
    /// folder whose owner file looks stale) was removed, and so, when running as root, was
    /// another user's folder.
    #[test]
    fn the_sweep_leaves_links_and_other_users_folders() {
        let tmp = tempfile::tempdir().unwrap();
        let stale = |dir: &Path| {
            std::fs::create_dir_all(dir).unwrap();
            std::fs::write(dir.join(OWNER), "4194303 1\n").unwrap();
        };
        let target = tmp.path().join("a-users-folder");
        stale(&target);
        let link = tmp.path().join("clevrtex-work-link");
        std::os::unix::fs::symlink(&target, &link).unwrap();
        let theirs = tmp.path().join("clevrtex-work-theirs");
        stale(&theirs);
        let foreign = std::os::unix::fs::chown(&theirs, Some(65534), Some(65534)).is_ok();
        let dead = tmp.path().join("clevrtex-work-dead");
        stale(&dead);
        // Without root, chown fails and that folder is ours (and removed) too.
        assert_eq!(remove_stale_in(tmp.path()), if foreign { 1 } else { 2 });
        assert!(!dead.exists());
        assert!(link.symlink_metadata().is_ok() && target.join(OWNER).exists());
        assert_eq!(theirs.exists(), foreign, "another user's folder is kept");
    }
}
