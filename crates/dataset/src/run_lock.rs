//! One writer per range: a `generate` run holds a lock on the indices it makes, so a second
//! run whose indices overlap (the same command started twice, or `--start`/`-n` ranges that
//! meet) refuses to start instead of writing the same samples at the same time.
//!
//! `OUT/clevrtex_<variant>/.clevrtex-run-<start>-<end>-<k>of<n>.lock`, JSON: the holder's
//! `host`, `pid` and `pid_start` (its start time, so a new process with the same pid is not
//! taken for it), the range, the shard and the command. Locks are taken and checked under an
//! exclusive `flock` of `.clevrtex-runs.lock` in the same folder (kept), so two runs starting at once
//! cannot both pass. A lock is stale, and ignored (then replaced), when its holder is gone:
//! on this host, when no process with its pid and start time runs; on another host (a cluster
//! node, a pod), when its file was not touched for [`STALE_AFTER`] (the holder touches it every
//! [`HEARTBEAT`]). The lock is removed when the run ends (also on Ctrl-C or an error).

use std::path::{Path, PathBuf};
use std::sync::mpsc;
use std::time::{Duration, SystemTime};

use serde::{Deserialize, Serialize};

use clevrtex_scene::text::printable;

/// How often a holder touches its lock file.
pub const HEARTBEAT: Duration = Duration::from_secs(20);
/// A lock of another host not touched for this long is stale.
pub const STALE_AFTER: Duration = Duration::from_secs(120);
/// The file whose `flock` guards checking and taking locks (kept, like the ledger's).
pub const GUARD: &str = ".clevrtex-runs.lock";
/// Prefix of lock files.
const PREFIX: &str = ".clevrtex-run-";
/// The largest lock file read (a lock is a few hundred bytes).
const MAX_LOCK_BYTES: u64 = 64 * 1024;

/// What a lock file holds.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct Holder {
    /// Host name of the holder ([`crate::atomic::hostname`]).
    pub host: String,
    /// Its process id.
    pub pid: u32,
    /// Its start time (clock ticks since boot; 0: unknown).
    pub pid_start: u64,
    /// First index of its range.
    pub start: u64,
    /// One past its last index.
    pub end: u64,
    /// Its shard `[k, n]`.
    pub shard: [u64; 2],
    /// Its command line.
    pub command: Vec<String>,
}

/// A held lock; dropping it removes the lock file.
#[derive(Debug)]
pub struct RunLock {
    path: PathBuf,
    stop: Option<mpsc::Sender<()>>,
    beat: Option<std::thread::JoinHandle<()>>,
}

/// File name of the lock of a range and shard.
pub fn file_name(start: u64, end: u64, k: u64, n: u64) -> String {
    format!("{PREFIX}{start}-{end}-{k}of{n}.lock")
}

/// Whether some index of `start..end` is in both shards `[k1, n1]` and `[k2, n2]` of the
/// two ranges.
pub fn overlaps(a: (u64, u64, [u64; 2]), b: (u64, u64, [u64; 2])) -> bool {
    let (lo, hi) = (a.0.max(b.0), a.1.min(b.1));
    if lo >= hi {
        return false;
    }
    let ([k1, n1], [k2, n2]) = (a.2, b.2);
    let (n1, n2) = (n1.max(1), n2.max(1));
    // The first index of `lo..hi` in shard 1, then every n1-th: their residues mod n2 repeat
    // after n2 steps, so n2 steps decide (bounded; past the bound, assume an overlap).
    let first = lo + (k1 % n1 + n1 - lo % n1) % n1;
    let mut i = first;
    for _ in 0..n2.min(1_000_000) {
        if i >= hi {
            return false;
        }
        if i % n2 == k2 % n2 {
            return true;
        }
        i = match i.checked_add(n1) {
            Some(v) => v,
            None => return false,
        };
    }
    n2 > 1_000_000
}

/// Open (creating it) the lock file `path` of a variant folder, to `flock` it: the run lock's
/// guard ([`GUARD`]) and the failure ledger's. The folder may be a dataset handed over, so
/// nothing in its place is trusted: the file is opened without following a link (a link,
/// dangling or not, could create or lock a file outside the dataset) and without blocking (a
/// FIFO would block the open for good), and must be a regular file. Anything else is refused
/// with a message naming it. Opened for writing: on NFS `flock` is emulated with POSIX locks,
/// which need a writable descriptor.
pub fn open_lock_file(path: &Path) -> Result<std::fs::File, String> {
    use std::os::unix::fs::OpenOptionsExt;
    let refuse = |what: &str| {
        format!(
            "`{}` {what}, where clevrtex keeps a lock file; it is not opened\nhint: delete it (clevrtex makes this file itself, a regular file) and run again",
            path.display()
        )
    };
    let kind = |meta: &std::fs::Metadata| {
        if meta.file_type().is_symlink() {
            "is a symbolic link"
        } else {
            "is not a regular file (a FIFO, socket, device or folder)"
        }
    };
    let opened = std::fs::OpenOptions::new()
        .create(true)
        .truncate(false)
        .write(true)
        .custom_flags(no_follow_no_block())
        .open(path);
    let file = match opened {
        Ok(f) => f,
        Err(e) => {
            return Err(match std::fs::symlink_metadata(path) {
                Ok(m) if !m.is_file() => refuse(kind(&m)),
                _ => format!(
                    "cannot create `{}`: {e}\nhint: pass a writable folder with `--out`",
                    path.display()
                ),
            })
        }
    };
    match file.metadata() {
        Ok(m) if m.is_file() => Ok(file),
        Ok(m) => Err(refuse(kind(&m))),
        Err(e) => Err(format!("cannot read `{}`: {e}", path.display())),
    }
}

/// Whether the holder of a lock file (its `holder`, the file's modification time) is gone.
fn is_stale(holder: &Holder, modified: Option<SystemTime>) -> bool {
    if holder.host == crate::atomic::hostname() {
        // A start time of 0 (unknown) proves nothing: where this host's start times can be
        // read (always on Linux), a run here wrote its own, and where they cannot, no pid is
        // known to be alive either. So a lock naming this host with `pid_start` 0 (a file
        // someone wrote, e.g. naming pid 1) is stale.
        return holder.pid_start == 0
            || !crate::atomic::process_alive(holder.pid, holder.pid_start);
    }
    modified
        .and_then(|m| SystemTime::now().duration_since(m).ok())
        .is_some_and(|age| age > STALE_AFTER)
}

/// The range locks of live runs in `variant_dir` (stale ones left out), each with its file.
/// Call it under the guard's `flock` ([`Quiet`], [`RunLock::acquire`]), so no run takes a
/// lock meanwhile. `Err` when a lock file cannot be read: whether a run is writing is unknown.
fn live_holders(variant_dir: &Path) -> Result<Vec<(PathBuf, Holder)>, String> {
    let io = |p: &Path, e: std::io::Error| {
        format!(
            "cannot read `{}`: {e}\nhint: pass a readable folder",
            p.display()
        )
    };
    let root = crate::dataset::files::root(variant_dir).map_err(|e| io(variant_dir, e))?;
    let entries =
        crate::dataset::files::list(&root, variant_dir).map_err(|e| io(variant_dir, e))?;
    let mut live = Vec::new();
    for (name, path, _) in entries {
        if !(name.starts_with(PREFIX) && name.ends_with(".lock")) {
            continue;
        }
        let holder = crate::dataset::files::read(&root, &path, MAX_LOCK_BYTES)
            .and_then(|b| serde_json::from_slice::<Holder>(&b).map_err(|e| e.to_string()));
        let holder = match holder {
            Ok(h) => h,
            Err(why) => {
                return Err(format!(
                    "the run lock `{}` cannot be read ({why}), so this run cannot tell whether another run is writing here\nhint: if no `clevrtex generate` is writing into `{}`, delete `{}` and run again",
                    path.display(),
                    variant_dir.display(),
                    path.display()
                ))
            }
        };
        let modified = std::fs::symlink_metadata(&path)
            .and_then(|m| m.modified())
            .ok();
        if !is_stale(&holder, modified) {
            live.push((path, holder));
        }
    }
    Ok(live)
}

impl Holder {
    /// Whether index `index` is one this holder's run writes (in its range and shard).
    pub fn covers(&self, index: u64) -> bool {
        index < u64::MAX
            && overlaps(
                (index, index + 1, [0, 1]),
                (self.start, self.end, self.shard),
            )
    }

    /// `pid P on host `H` (indices A..B, shard k/n)`, for messages.
    pub fn describe(&self) -> String {
        format!(
            "pid {} on host `{}` (indices {}..{}, shard {}/{})",
            self.pid,
            printable(&self.host),
            self.start,
            self.end,
            self.shard[0],
            self.shard[1]
        )
    }
}

/// The live runs of a variant folder, held still: while a `Quiet` lives, the guard's `flock`
/// is held, so no run can take a range lock (a `generate` starting meanwhile waits for it).
/// What removes files from a folder a run may be writing into (`verify --remove-broken`)
/// holds one, and leaves alone every index a live run [`Holder::covers`].
#[derive(Debug)]
pub struct Quiet {
    _guard: std::fs::File,
    /// The locks of live runs.
    pub live: Vec<Holder>,
}

impl Quiet {
    /// Hold `variant_dir` (an existing variant folder) still and read its live runs' locks.
    pub fn hold(variant_dir: &Path) -> Result<Quiet, String> {
        let guard_path = variant_dir.join(GUARD);
        let guard = open_lock_file(&guard_path)?;
        guard.lock().map_err(|e| {
            format!(
                "cannot lock `{}`: {e}\nhint: pass a writable folder",
                guard_path.display()
            )
        })?;
        let live = live_holders(variant_dir)?
            .into_iter()
            .map(|(_, h)| h)
            .collect();
        Ok(Quiet {
            _guard: guard,
            live,
        })
    }

    /// The live run writing index `index`, if any.
    pub fn writer_of(&self, index: u64) -> Option<&Holder> {
        self.live.iter().find(|h| h.covers(index))
    }
}

impl RunLock {
    /// Take the lock of shard `[k, n]` of `start..end` in `variant_dir` (created if missing).
    /// `Err` (a message with a `hint:` line) when a live run holds an overlapping range, naming
    /// its lock file and holder.
    pub fn acquire(
        variant_dir: &Path,
        start: u64,
        end: u64,
        shard: [u64; 2],
        command: Vec<String>,
    ) -> Result<RunLock, String> {
        let io = |what: &str, p: &Path, e: std::io::Error| {
            format!(
                "cannot {what} `{}`: {e}\nhint: pass a writable folder with `--out`",
                p.display()
            )
        };
        // The variant folder of `--out`: a link out of it is refused, naming it.
        let out = variant_dir.parent().unwrap_or(Path::new("."));
        crate::layout::make_dir(out, variant_dir)?;
        let guard_path = variant_dir.join(GUARD);
        let guard = open_lock_file(&guard_path)?;
        guard.lock().map_err(|e| io("lock", &guard_path, e))?;
        for (path, holder) in live_holders(variant_dir)? {
            if overlaps(
                (start, end, shard),
                (holder.start, holder.end, holder.shard),
            ) {
                return Err(format!(
                    "indices {start}..{end} (shard {}/{}) overlap those of another run writing into `{}`: pid {} on host `{}` holds indices {}..{} (shard {}/{}) in the lock `{}` (its command: {})\nhint: wait for that run to end, or give this run another `--out` or a range that does not overlap; if that run is gone (its machine stopped), delete `{}` and run again",
                    shard[0],
                    shard[1],
                    variant_dir.display(),
                    holder.pid,
                    printable(&holder.host),
                    holder.start,
                    holder.end,
                    holder.shard[0],
                    holder.shard[1],
                    path.display(),
                    printable(&holder.command.join(" ")),
                    path.display()
                ));
            }
        }
        let holder = Holder {
            host: crate::atomic::hostname(),
            pid: std::process::id(),
            pid_start: crate::atomic::own_start_time(),
            start,
            end,
            shard,
            command,
        };
        let path = variant_dir.join(file_name(start, end, shard[0], shard[1]));
        let text = serde_json::to_string_pretty(&holder).expect("lock serialises") + "\n";
        crate::atomic::write(&path, text.as_bytes()).map_err(|e| io("write", &path, e))?;
        drop(guard);
        let (tx, rx) = mpsc::channel::<()>();
        let beat_path = path.clone();
        let beat = std::thread::spawn(move || {
            use std::os::unix::fs::OpenOptionsExt;
            while let Err(mpsc::RecvTimeoutError::Timeout) = rx.recv_timeout(HEARTBEAT) {
                if let Ok(f) = std::fs::OpenOptions::new()
                    .append(true)
                    .custom_flags(no_follow_no_block())
                    .open(&beat_path)
                {
                    let _ = f.set_modified(SystemTime::now());
                }
            }
        });
        Ok(RunLock {
            path,
            stop: Some(tx),
            beat: Some(beat),
        })
    }

    /// The lock file.
    pub fn path(&self) -> &Path {
        &self.path
    }
}

impl Drop for RunLock {
    fn drop(&mut self) {
        drop(self.stop.take());
        if let Some(b) = self.beat.take() {
            let _ = b.join();
        }
        // Remove the file only while it is still ours (never another run's lock).
        let ours = crate::dataset::files::read_regular(&self.path, MAX_LOCK_BYTES)
            .ok()
            .and_then(|b| serde_json::from_slice::<Holder>(&b).ok())
            .is_some_and(|h| h.pid == std::process::id() && h.host == crate::atomic::hostname());
        if ours {
            let _ = std::fs::remove_file(&self.path);
        }
    }
}

/// `O_NOFOLLOW | O_NONBLOCK`, for [`std::os::unix::fs::OpenOptionsExt::custom_flags`]: how a
/// file in an output folder that may hold anyone's files is opened (a link in its place is
/// not followed, a FIFO does not block).
fn no_follow_no_block() -> i32 {
    (rustix::fs::OFlags::NOFOLLOW | rustix::fs::OFlags::NONBLOCK).bits() as i32
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn overlapping_ranges_and_shards() {
        assert!(overlaps((0, 8, [0, 1]), (4, 12, [0, 1])));
        assert!(!overlaps((0, 8, [0, 1]), (8, 12, [0, 1])));
        assert!(!overlaps((0, 8, [0, 2]), (0, 8, [1, 2])));
        assert!(overlaps((0, 8, [0, 2]), (0, 8, [0, 4])));
        assert!(!overlaps((0, 8, [1, 2]), (0, 8, [0, 4])));
        assert!(overlaps((3, 4, [0, 3]), (0, 8, [0, 1])));
        assert!(!overlaps((4, 5, [0, 3]), (0, 8, [0, 1])));
        assert!(overlaps((0, u64::MAX, [5, 7]), (0, u64::MAX, [1, 3])));
    }

    #[test]
    fn a_live_overlapping_lock_refuses_and_a_dead_ones_is_replaced() {
        let dir = tempfile::tempdir().unwrap();
        let a = RunLock::acquire(dir.path(), 0, 8, [0, 1], vec!["a".into()]).unwrap();
        let err = RunLock::acquire(dir.path(), 4, 12, [0, 1], vec!["b".into()]).unwrap_err();
        assert!(
            err.contains(&format!("pid {}", std::process::id())),
            "{err}"
        );
        assert!(err.contains(".clevrtex-run-0-8-0of1.lock"), "{err}");
        let b = RunLock::acquire(dir.path(), 8, 12, [0, 1], vec!["c".into()]).unwrap();
        drop(a);
        assert!(!dir.path().join(file_name(0, 8, 0, 1)).exists());
        drop(b);
        // A holder that has exited on this host: stale.
        let mut child = std::process::Command::new("true").spawn().unwrap();
        let pid = child.id();
        child.wait().unwrap();
        let dead = Holder {
            host: crate::atomic::hostname(),
            pid,
            pid_start: 1,
            start: 0,
            end: 8,
            shard: [0, 1],
            command: vec![],
        };
        plant(dir.path(), &dead);
        let c = RunLock::acquire(dir.path(), 0, 8, [0, 1], vec![]).unwrap();
        drop(c);
        // Another host's lock, recently touched: live.
        let other = Holder {
            host: "elsewhere".into(),
            ..dead
        };
        plant(dir.path(), &other);
        let err = RunLock::acquire(dir.path(), 0, 8, [0, 1], vec![]).unwrap_err();
        assert!(err.contains("host `elsewhere`"), "{err}");
    }

    /// Write `holder` as the lock of the run 0..8 (one shard) in `dir`, as another run would.
    fn plant(dir: &Path, holder: &Holder) {
        std::fs::write(
            dir.join(file_name(0, 8, 0, 1)),
            serde_json::to_string(holder).unwrap(),
        )
        .unwrap();
    }

    #[test]
    fn a_holder_of_this_host_with_an_unknown_start_time_is_stale() {
        let dir = tempfile::tempdir().unwrap();
        let forged = Holder {
            host: crate::atomic::hostname(),
            pid: 1,
            pid_start: 0,
            start: 0,
            end: 8,
            shard: [0, 1],
            command: vec![],
        };
        plant(dir.path(), &forged);
        let lock = RunLock::acquire(dir.path(), 0, 8, [0, 1], vec![]);
        assert!(lock.is_ok(), "{lock:?}");
    }

    #[test]
    fn a_lock_file_that_is_a_link_or_a_fifo_is_refused_unopened() {
        let dir = tempfile::tempdir().unwrap();
        let outside = dir.path().join("outside");
        let lock = dir.path().join(GUARD);
        std::os::unix::fs::symlink(&outside, &lock).unwrap();
        let err = open_lock_file(&lock).unwrap_err();
        assert!(
            err.contains("is a symbolic link") && err.contains(GUARD),
            "{err}"
        );
        assert!(!outside.exists(), "created through the link");
        std::fs::remove_file(&lock).unwrap();
        let st = std::process::Command::new("mkfifo")
            .arg(&lock)
            .status()
            .unwrap();
        assert!(st.success());
        let err = open_lock_file(&lock).unwrap_err();
        assert!(err.contains("not a regular file"), "{err}");
        assert!(open_lock_file(&dir.path().join("plain.lock")).is_ok());
    }
}
