//! The one way this tool writes a file: [`AtomicFile`] (and [`write()`] for bytes at hand).
//!
//! A file is written under a temporary name beside its final one and renamed over it once
//! complete and synced, so a reader (or a rerun after a kill) sees the old file or the new
//! one, never a part. The temporary's name is unique to this process and machine
//! (`<name>.<host>.<pid>.<start>.clevrtex-tmp`, [`owner_tag`]), so shards and runs writing
//! into one shared folder never share one and a later run can tell a dead writer's leftovers
//! ([`tagged_name_is_stale`]). It is created exclusively (`O_CREAT | O_EXCL`) and without
//! following a link (`O_NOFOLLOW`): a link or file planted at that name is never written
//! through, truncated or removed (another name is tried). It is removed on every error path
//! and when dropped uncommitted; nothing else is ever removed.
//!
//! Every writer uses it: `generate`'s samples (`clevrtex_render::output::Staged`), manifests,
//! range locks and the failure ledger, `export`'s tars and `index.json`, `preview`, `report`,
//! `verify --json`, `eval --json/--csv`, `sample`'s scene files, `bench` and `materials`
//! outputs.

use std::io::Write;
use std::path::{Path, PathBuf};

use crate::layout::TMP_SUFFIX;

/// Start time of process `pid` (field 22 of `/proc/<pid>/stat`: clock ticks since boot), if
/// it is running.
pub fn start_time(pid: u32) -> Option<u64> {
    let stat = std::fs::read_to_string(format!("/proc/{pid}/stat")).ok()?;
    // The command name (field 2) may hold spaces and parentheses: fields resume after the
    // last `)`, at field 3.
    let rest = &stat[stat.rfind(')')? + 1..];
    rest.split_whitespace().nth(19)?.parse().ok()
}

/// Whether process `pid` of this machine, started at `start` (clock ticks since boot, as in
/// [`owner_tag`]; 0: unknown), is still running.
pub fn process_alive(pid: u32, start: u64) -> bool {
    start_time(pid).is_some_and(|s| start == 0 || s == start)
}

/// Start time of this process (clock ticks since boot; 0 where unknown).
pub fn own_start_time() -> u64 {
    start_time(std::process::id()).unwrap_or(0)
}

/// The variable that names this process's host in owner tags and range locks instead of the
/// machine's name. The Kubernetes recipe sets it to `<job>-<completion index>`, so that a pod
/// restarted for the same index (a new pod name, hence a new host name) knows a killed pod's
/// temporaries and lock in the shared output folder as its own host's, and finds them stale
/// when their pid and start time are not running.
pub const HOST_ENV: &str = "CLEVRTEX_HOST";

/// The host name of owner tags and range locks: `$CLEVRTEX_HOST` when set, else this
/// machine's name (`/proc/sys/kernel/hostname`).
pub fn hostname() -> String {
    static HOST: std::sync::OnceLock<String> = std::sync::OnceLock::new();
    HOST.get_or_init(|| {
        host_name(
            std::env::var(HOST_ENV).ok(),
            std::fs::read_to_string("/proc/sys/kernel/hostname")
                .or_else(|_| std::fs::read_to_string("/etc/hostname"))
                .ok(),
        )
    })
    .clone()
}

/// [`hostname`] from the variable's value and the machine's name: the first non-empty one,
/// as one tag-safe word (ASCII letters, digits and `-`; anything else becomes `_`, so a value
/// never adds a `.` to a tag or a `/` to a path).
fn host_name(var: Option<String>, machine: Option<String>) -> String {
    [var, machine]
        .into_iter()
        .flatten()
        .map(|h| h.trim().to_string())
        .find(|h| !h.is_empty())
        .unwrap_or_else(|| "localhost".into())
        .replace(|c: char| !(c.is_ascii_alphanumeric() || c == '-'), "_")
}

/// `<host>.<pid>.<start time>` of this process: put in the names of temporary files in shared
/// output folders, so a run can tell its own and other live runs' files (SLURM tasks or
/// Kubernetes pods writing into one folder) from those a killed run left.
pub fn owner_tag() -> String {
    static TAG: std::sync::OnceLock<String> = std::sync::OnceLock::new();
    TAG.get_or_init(|| {
        let pid = std::process::id();
        format!("{}.{pid}.{}", hostname(), start_time(pid).unwrap_or(0))
    })
    .clone()
}

/// Whether a file name carrying an [`owner_tag`] (`<anything>.<host>.<pid>.<start>` before
/// its suffix) belongs to a process that is gone. Files of another machine are never judged
/// stale (their owner may be running there); names without a tag (older versions) are.
pub fn tagged_name_is_stale(stem: &str) -> bool {
    let mut parts = stem.rsplitn(4, '.');
    let (Some(start), Some(pid), Some(host)) = (parts.next(), parts.next(), parts.next()) else {
        return true;
    };
    let (Ok(start), Ok(pid)) = (start.parse::<u64>(), pid.parse::<u32>()) else {
        return true;
    };
    if host != hostname() {
        return false;
    }
    !process_alive(pid, start)
}

/// How many names are tried when something already sits at a temporary's name.
const NAME_TRIES: u32 = 64;

/// Open `path` for writing: created exclusively, no link followed, no FIFO blocking.
fn create_exclusive(path: &Path) -> std::io::Result<std::fs::File> {
    use std::os::unix::fs::OpenOptionsExt;
    let flags = rustix::fs::OFlags::NOFOLLOW | rustix::fs::OFlags::NONBLOCK;
    std::fs::OpenOptions::new()
        .write(true)
        .create_new(true)
        .custom_flags(flags.bits() as i32)
        .open(path)
}

/// A file being written under a unique temporary name beside `path` until
/// [`AtomicFile::commit`]; dropped uncommitted (an error, a panic), its temporary is removed.
#[derive(Debug)]
pub struct AtomicFile {
    tmp: PathBuf,
    path: PathBuf,
    file: Option<std::fs::File>,
}

impl AtomicFile {
    /// Start writing the future `path` (its folder must exist). Errors are the OS's; callers
    /// name `path` in their message.
    pub fn create(path: &Path) -> std::io::Result<AtomicFile> {
        let name = path
            .file_name()
            .ok_or_else(|| std::io::Error::other("not a file name"))?
            .to_string_lossy()
            .into_owned();
        let dir = match path.parent() {
            Some(p) if !p.as_os_str().is_empty() => p,
            _ => Path::new("."),
        };
        let tag = owner_tag();
        let mut last = None;
        for k in 0..NAME_TRIES {
            // `<name>.<tag>` first (what `generate` always wrote), then `<name>-<k>.<tag>`
            // when something sits there (a planted file or link is left alone).
            let tmp_name = if k == 0 {
                format!("{name}.{tag}{TMP_SUFFIX}")
            } else {
                format!("{name}-{k}.{tag}{TMP_SUFFIX}")
            };
            let tmp = dir.join(tmp_name);
            match create_exclusive(&tmp) {
                Ok(file) => {
                    return Ok(AtomicFile {
                        tmp,
                        path: path.to_path_buf(),
                        file: Some(file),
                    })
                }
                Err(e) if e.kind() == std::io::ErrorKind::AlreadyExists => last = Some(e),
                Err(e) => return Err(e),
            }
        }
        Err(last.unwrap_or_else(|| std::io::Error::other("no temporary name free")))
    }

    /// The temporary's path (for messages).
    pub fn tmp_path(&self) -> &Path {
        &self.tmp
    }

    /// The final path.
    pub fn path(&self) -> &Path {
        &self.path
    }

    fn file(&mut self) -> std::io::Result<&mut std::fs::File> {
        self.file
            .as_mut()
            .ok_or_else(|| std::io::Error::other("already committed"))
    }

    /// Sync the bytes written to disk (done by [`AtomicFile::commit`] too): what a writer of
    /// several files calls before renaming any of them.
    pub fn sync(&mut self) -> std::io::Result<()> {
        self.file()?.sync_all()
    }

    /// Sync and rename the temporary over the final path (a link there is replaced, never
    /// followed), then sync the folder. On error the temporary is removed and the final path
    /// is as it was.
    pub fn commit(mut self) -> std::io::Result<()> {
        let file = self
            .file
            .take()
            .ok_or_else(|| std::io::Error::other("committed twice"))?;
        file.sync_all()?;
        drop(file);
        std::fs::rename(&self.tmp, &self.path)?;
        // Renamed: nothing of ours left to remove.
        self.tmp = PathBuf::new();
        if let Some(dir) = self.path.parent().filter(|p| !p.as_os_str().is_empty()) {
            if let Ok(d) = std::fs::File::open(dir) {
                let _ = d.sync_all();
            }
        }
        Ok(())
    }
}

impl AtomicFile {
    /// Rename the temporary over the final path without syncing the file or its folder: for a
    /// writer of many small files, which makes them durable once at the end
    /// ([`sync_filesystem`]) and then writes its manifest, the commit point. Readers see the
    /// old file or the whole new one; after a power loss before that sync the new file may be
    /// empty or missing, which only the manifest's absence tells.
    pub fn commit_unsynced(mut self) -> std::io::Result<()> {
        let file = self
            .file
            .take()
            .ok_or_else(|| std::io::Error::other("committed twice"))?;
        drop(file);
        std::fs::rename(&self.tmp, &self.path)?;
        self.tmp = PathBuf::new();
        Ok(())
    }
}

/// [`write`] without the syncs ([`AtomicFile::commit_unsynced`]): the writer makes the files
/// durable once ([`sync_filesystem`]) before it commits them with its manifest.
pub fn write_unsynced(path: &Path, bytes: &[u8]) -> std::io::Result<()> {
    let mut f = AtomicFile::create(path)?;
    f.write_all(bytes)?;
    f.commit_unsynced()
}

/// Remove temporary files a killed run left in `dir` (not recursive). Temporary names carry
/// their writer's owner tag ([`owner_tag`]): files of live runs (other shards writing into the
/// same folder) and of other machines are left alone.
pub fn remove_stale_temps(dir: &Path) {
    let Ok(root) = crate::dataset::root(dir) else {
        return;
    };
    for (name, path, kind) in crate::dataset::list(&root, dir).unwrap_or_default() {
        if let Some(stem) = name.strip_suffix(TMP_SUFFIX) {
            if kind == crate::dataset::Kind::File && tagged_name_is_stale(stem) {
                let _ = std::fs::remove_file(path);
            }
        }
    }
}

/// Make everything written so far on the file system that holds `dir` durable: one
/// `syncfs(2)` instead of a sync per file and folder.
pub fn sync_filesystem(dir: &Path) -> std::io::Result<()> {
    let f = std::fs::File::open(dir)?;
    rustix::fs::syncfs(&f)?;
    Ok(())
}

impl Write for AtomicFile {
    fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
        self.file()?.write(buf)
    }

    fn flush(&mut self) -> std::io::Result<()> {
        self.file()?.flush()
    }
}

impl Drop for AtomicFile {
    fn drop(&mut self) {
        if !self.tmp.as_os_str().is_empty() {
            self.file = None;
            let _ = std::fs::remove_file(&self.tmp);
        }
    }
}

/// Write `bytes` as `path` through an [`AtomicFile`]: `path` holds its old contents or all of
/// `bytes`, and no temporary is left on any error (a full disk included).
pub fn write(path: &Path, bytes: &[u8]) -> std::io::Result<()> {
    let mut f = AtomicFile::create(path)?;
    f.write_all(bytes)?;
    f.commit()
}

/// Make sure the output root `out` exists and a file can be created in it, before any
/// rendering: a temporary of the one atomic writer, dropped unrenamed (nothing is left, and
/// nothing planted there is written through or removed).
pub fn check_writable(out: &Path) -> Result<(), String> {
    let hint = "hint: pass a writable folder with `--out`";
    std::fs::create_dir_all(out).map_err(|e| {
        format!(
            "cannot create output folder `{}`: {e}\n{hint}",
            out.display()
        )
    })?;
    AtomicFile::create(&out.join(".clevrtex-write-test")).map_err(|e| {
        format!(
            "cannot write in output folder `{}`: {e}\n{hint}",
            out.display()
        )
    })?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_host_variable_names_the_host_as_one_tag_safe_word() {
        let m = Some("node-7\n".to_string());
        assert_eq!(host_name(None, m.clone()), "node-7");
        assert_eq!(
            host_name(Some("gen-full-3".into()), m.clone()),
            "gen-full-3"
        );
        assert_eq!(host_name(Some("  ".into()), m.clone()), "node-7");
        assert_eq!(host_name(Some("../a.b/c".into()), m), "___a_b_c");
        assert_eq!(host_name(None, None), "localhost");
    }

    #[test]
    fn owner_tags_tell_live_dead_and_foreign_owners() {
        let me = format!("x.png.{}", owner_tag());
        assert!(!tagged_name_is_stale(&me));
        let dead = format!("x.png.{}.4194303.1", hostname());
        assert!(tagged_name_is_stale(&dead));
        assert!(!tagged_name_is_stale("x.png.some-other-host.4194303.1"));
        assert!(tagged_name_is_stale("x.png"));
    }

    fn names(dir: &Path) -> Vec<String> {
        let mut v: Vec<String> = std::fs::read_dir(dir)
            .unwrap()
            .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
            .collect();
        v.sort();
        v
    }

    /// A link planted at the temporary's name (which is predictable) is neither written
    /// through nor removed, and the output is a regular file, not the link.
    #[test]
    fn a_link_at_the_temporary_name_is_not_followed_or_removed() {
        let dir = tempfile::tempdir().unwrap();
        let outside = tempfile::tempdir().unwrap();
        let victim = outside.path().join("victim");
        std::fs::write(&victim, b"theirs").unwrap();
        let out = dir.path().join("a.tar");
        let planted = dir
            .path()
            .join(format!("a.tar.{}{TMP_SUFFIX}", owner_tag()));
        std::os::unix::fs::symlink(&victim, &planted).unwrap();
        write(&out, b"ours").unwrap();
        assert_eq!(std::fs::read(&victim).unwrap(), b"theirs");
        assert!(planted.symlink_metadata().unwrap().file_type().is_symlink());
        let meta = out.symlink_metadata().unwrap();
        assert!(meta.is_file());
        assert_eq!(std::fs::read(&out).unwrap(), b"ours");
        assert_eq!(names(outside.path()), ["victim"]);
    }

    /// A user's own file at a temporary's name is never removed, on error paths included;
    /// an uncommitted file leaves nothing.
    #[test]
    fn errors_and_drops_leave_no_temporary_and_remove_nothing_else() {
        let dir = tempfile::tempdir().unwrap();
        let theirs = dir
            .path()
            .join(format!("x.json.{}{TMP_SUFFIX}", owner_tag()));
        std::fs::write(&theirs, b"user data").unwrap();
        // The final path is a folder: the rename fails, the temporary goes, theirs stays.
        std::fs::create_dir(dir.path().join("x.json")).unwrap();
        assert!(write(&dir.path().join("x.json"), b"{}").is_err());
        assert_eq!(std::fs::read(&theirs).unwrap(), b"user data");
        assert_eq!(names(dir.path()).len(), 2, "{:?}", names(dir.path()));
        {
            let mut f = AtomicFile::create(&dir.path().join("y.json")).unwrap();
            f.write_all(b"half").unwrap();
        }
        assert_eq!(names(dir.path()).len(), 2, "{:?}", names(dir.path()));
    }

    /// A full disk (`/dev/full`'s error, ENOSPC) at the write leaves no temporary, so no
    /// 0-byte file outlives the run.
    #[test]
    fn a_full_disk_leaves_no_temporary() {
        let dir = tempfile::tempdir().unwrap();
        let mut f = AtomicFile::create(&dir.path().join("m.json")).unwrap();
        let tmp = f.tmp_path().to_path_buf();
        assert!(tmp.exists());
        // Swap the open file for `/dev/full`: every write fails as on a full disk.
        if let Ok(full) = std::fs::OpenOptions::new().write(true).open("/dev/full") {
            f.file = Some(full);
            assert!(f.write_all(b"{}").and_then(|()| f.flush()).is_err());
        }
        drop(f);
        assert!(!tmp.exists());
        assert!(names(dir.path()).is_empty());
    }
}
