//! Files of a dataset folder read and deleted without trusting it: its canonical root, what an
//! entry is ([`Kind`]: links followed only inside the root, no FIFO opened), capped reads, and
//! opens and deletes relative to a handle on the root ([`open_beneath`], [`remove_beneath`]).

use std::io::Read;
use std::path::{Path, PathBuf};

/// The largest file of a dataset that is read (1 GiB): far over any PNG of the largest
/// image, any metadata or any manifest this tool writes.
pub const MAX_FILE_BYTES: u64 = 1 << 30;

/// What a folder entry is, links resolved only inside the root.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Kind {
    /// A folder (or a link to a folder inside the root).
    Dir,
    /// A regular file (or a link to one inside the root).
    File,
    /// Not followed or not readable as data; the reason, one line.
    Skipped(String),
}

/// The canonical form of a dataset root (the command line's folder, trusted), to tell
/// whether a link leads out of it.
pub fn root(path: &Path) -> std::io::Result<PathBuf> {
    path.canonicalize()
}

/// What `path` (an entry found under `root`, a canonical root) is, without opening it.
pub fn classify(root: &Path, path: &Path) -> Kind {
    let Ok(meta) = std::fs::symlink_metadata(path) else {
        return Kind::Skipped("cannot be read".into());
    };
    let meta = if meta.file_type().is_symlink() {
        let Ok(target) = path.canonicalize() else {
            return Kind::Skipped("is a symbolic link to nothing".into());
        };
        if !target.starts_with(root) {
            return Kind::Skipped(format!(
                "is a symbolic link leading out of the dataset (to `{}`); not followed",
                target.display()
            ));
        }
        match std::fs::metadata(&target) {
            Ok(m) => m,
            Err(_) => return Kind::Skipped("is a symbolic link to nothing".into()),
        }
    } else {
        meta
    };
    if meta.is_dir() {
        Kind::Dir
    } else if meta.is_file() {
        Kind::File
    } else {
        Kind::Skipped("is not a regular file (a FIFO, socket or device); skipped".into())
    }
}

/// The entries of `dir` (a folder under `root`) by name, sorted, each with its [`Kind`].
pub fn list(root: &Path, dir: &Path) -> std::io::Result<Vec<(String, PathBuf, Kind)>> {
    let mut out: Vec<(String, PathBuf, Kind)> = std::fs::read_dir(dir)?
        .flatten()
        .map(|e| {
            let p = e.path();
            let kind = classify(root, &p);
            (e.file_name().to_string_lossy().into_owned(), p, kind)
        })
        .collect();
    out.sort_by(|a, b| a.0.cmp(&b.0));
    Ok(out)
}

#[cfg(target_os = "linux")]
const O_NONBLOCK: i32 = 0o4000;
#[cfg(not(target_os = "linux"))]
const O_NONBLOCK: i32 = 0x0004;

/// The bytes of the regular file `path` under `root`, at most `cap` bytes; `Err` says why
/// not, in one line (a link out of the root, not a regular file, too large, unreadable). The
/// file is opened relative to the root's folder handle ([`open_beneath`]), so a folder on the
/// way swapped for a link out of the dataset after it was walked is not read through.
pub fn read(root: &Path, path: &Path, cap: u64) -> Result<Vec<u8>, String> {
    if let Kind::Skipped(why) = classify(root, path) {
        return Err(why);
    }
    read_beneath(root, path, cap).map_err(|e| e.to_string())
}

/// The bytes of `path`, a file under the canonical `root`, opened relative to the root's
/// folder handle ([`open_beneath`]: no link leading out of the root followed, on any
/// component, whatever was swapped since the walk); a regular file only, at most `cap` bytes.
pub fn read_beneath(root: &Path, path: &Path, cap: u64) -> Result<Vec<u8>, ReadError> {
    read_open(open_file_beneath(root, path)?, cap)
}

/// `path` opened as [`read`] opens it (beneath `root`, [`open_beneath`]), for a reader that
/// streams it instead of holding its bytes: a regular file of at most `cap` bytes, read
/// through a [`std::io::Take`] of `cap + 1` bytes, so a file that grows past `cap` while it is
/// read still ends; `Err` says why not, in one line.
pub fn open_capped(
    root: &Path,
    path: &Path,
    cap: u64,
) -> Result<std::io::Take<std::fs::File>, String> {
    if let Kind::Skipped(why) = classify(root, path) {
        return Err(why);
    }
    let f = open_file_beneath(root, path).map_err(|e| e.to_string())?;
    checked_len(&f, cap).map_err(|e| e.to_string())?;
    Ok(f.take(cap + 1))
}

fn open_file_beneath(root: &Path, path: &Path) -> Result<std::fs::File, ReadError> {
    let rel = relative_to_root(root, path).ok_or(ReadError::LeadsOut)?;
    let fd = open_beneath(
        root,
        &rel,
        rustix::fs::OFlags::RDONLY | rustix::fs::OFlags::NONBLOCK,
    )
    .map_err(|e| {
        if is_leads_out(&e) {
            ReadError::LeadsOut
        } else {
            ReadError::Io(e)
        }
    })?;
    Ok(std::fs::File::from(fd))
}

/// `path` relative to the canonical `root`: its part after the deepest ancestor that resolves
/// to `root` (the folder given, whatever links the trusted command line's path holds). `None`
/// when no ancestor is the root.
pub fn relative_to_root(root: &Path, path: &Path) -> Option<PathBuf> {
    if let Ok(r) = path.strip_prefix(root) {
        return Some(r.to_path_buf());
    }
    for anc in path.ancestors().skip(1) {
        let a = if anc.as_os_str().is_empty() {
            Path::new(".")
        } else {
            anc
        };
        if a.canonicalize().is_ok_and(|c| c == root) {
            return path.strip_prefix(anc).ok().map(Path::to_path_buf);
        }
    }
    None
}

/// The marker of an [`open_beneath`] refusal: the path leads out of the root.
#[derive(Debug)]
struct LeadsOut;

impl std::fmt::Display for LeadsOut {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str("leads out of the dataset through a symbolic link; not followed")
    }
}

impl std::error::Error for LeadsOut {}

/// Whether `e` is [`open_beneath`]'s refusal of a path leading out of the root.
pub fn is_leads_out(e: &std::io::Error) -> bool {
    e.get_ref().is_some_and(|i| i.is::<LeadsOut>())
}

/// Most symbolic links resolved in one path (the kernel's own limit).
const MAX_LINKS: usize = 40;

/// Open `rel` (a path relative to the canonical, trusted `root`) with `flags`, resolving it
/// one component at a time from a handle on `root` (`openat` with `O_NOFOLLOW`, `readlinkat`):
/// a link is followed only while it stays inside the root (`..` never climbs above it, an
/// absolute target must lie under it); a component swapped for a link between two steps
/// makes its `O_NOFOLLOW` open fail, it is never followed. Refusals are [`is_leads_out`].
/// What `openat2(RESOLVE_BENEATH)` does, on every kernel.
pub fn open_beneath(
    root: &Path,
    rel: &Path,
    flags: rustix::fs::OFlags,
) -> std::io::Result<std::os::fd::OwnedFd> {
    use rustix::fs::{openat, readlinkat, statat, AtFlags, FileType, Mode, OFlags, CWD};
    use std::collections::VecDeque;
    use std::ffi::OsString;
    use std::os::unix::ffi::OsStrExt;
    use std::path::Component;
    let out = || std::io::Error::other(LeadsOut);
    let dir_flags = OFlags::RDONLY | OFlags::DIRECTORY | OFlags::NOFOLLOW | OFlags::CLOEXEC;
    let mut stack = vec![openat(
        CWD,
        root,
        OFlags::RDONLY | OFlags::DIRECTORY | OFlags::CLOEXEC,
        Mode::empty(),
    )?];
    // `None`: `..`; `Some(name)`: a name.
    let parts = |p: &Path| -> Result<Vec<Option<OsString>>, std::io::Error> {
        let mut v = Vec::new();
        for c in p.components() {
            match c {
                Component::CurDir => {}
                Component::ParentDir => v.push(None),
                Component::Normal(n) => v.push(Some(n.to_os_string())),
                Component::RootDir | Component::Prefix(_) => return Err(out()),
            }
        }
        Ok(v)
    };
    let mut todo: VecDeque<Option<OsString>> = parts(rel)?.into();
    let mut links = 0;
    while let Some(part) = todo.pop_front() {
        let Some(name) = part else {
            if stack.len() == 1 {
                return Err(out());
            }
            stack.pop();
            continue;
        };
        let cur = stack.last().expect("the root stays");
        let st = statat(cur, name.as_os_str(), AtFlags::SYMLINK_NOFOLLOW)?;
        if FileType::from_raw_mode(st.st_mode) == FileType::Symlink {
            links += 1;
            if links > MAX_LINKS {
                return Err(std::io::Error::from_raw_os_error(
                    rustix::io::Errno::LOOP.raw_os_error(),
                ));
            }
            let target = readlinkat(cur, name.as_os_str(), Vec::new())?;
            let target = Path::new(std::ffi::OsStr::from_bytes(target.as_bytes())).to_path_buf();
            let next = if target.is_absolute() {
                let inside = target.strip_prefix(root).map_err(|_| out())?;
                stack.truncate(1);
                parts(inside)?
            } else {
                parts(&target)?
            };
            for p in next.into_iter().rev() {
                todo.push_front(p);
            }
            continue;
        }
        if todo.is_empty() {
            return Ok(openat(
                cur,
                name.as_os_str(),
                flags | OFlags::NOFOLLOW | OFlags::CLOEXEC,
                Mode::empty(),
            )?);
        }
        let fd = openat(cur, name.as_os_str(), dir_flags, Mode::empty())?;
        stack.push(fd);
    }
    let cur = stack.last().expect("the root stays");
    Ok(openat(cur, ".", flags | OFlags::CLOEXEC, Mode::empty())?)
}

/// Remove the file `name` (a link as a link) from the folder `dir_handle`, opened once
/// relative to its dataset's root ([`open_dir_beneath`]): a folder swapped for a link leading
/// out of the dataset after that is not deleted through. Returns whether a file was removed
/// (`false`: none there, or a folder).
pub fn remove_beneath(dir_handle: &std::os::fd::OwnedFd, name: &str) -> std::io::Result<bool> {
    use rustix::fs::{statat, unlinkat, AtFlags, FileType};
    match statat(dir_handle, name, AtFlags::SYMLINK_NOFOLLOW) {
        Ok(st) if FileType::from_raw_mode(st.st_mode) != FileType::Directory => {
            match unlinkat(dir_handle, name, AtFlags::empty()) {
                Ok(()) => Ok(true),
                Err(rustix::io::Errno::NOENT) => Ok(false),
                Err(e) => Err(e.into()),
            }
        }
        Ok(_) | Err(rustix::io::Errno::NOENT) => Ok(false),
        Err(e) => Err(e.into()),
    }
}

/// A handle on `dir`, a folder under one of the canonical `roots`, opened relative to that
/// root ([`open_beneath`]); what deletes in a dataset go through ([`remove_beneath`]).
pub fn open_dir_beneath(
    roots: &[PathBuf],
    dir: &Path,
) -> std::io::Result<(PathBuf, std::os::fd::OwnedFd)> {
    let (root, rel) = roots
        .iter()
        .find_map(|r| relative_to_root(r, dir).map(|rel| (r.clone(), rel)))
        .ok_or_else(|| std::io::Error::other(LeadsOut))?;
    let fd = open_beneath(
        &root,
        &rel,
        rustix::fs::OFlags::RDONLY | rustix::fs::OFlags::DIRECTORY,
    )?;
    Ok((root, fd))
}

/// Why [`read_regular`] read nothing. Shown as one line without the path.
#[derive(Debug)]
pub enum ReadError {
    /// The file cannot be opened or read (the OS error, its kind and number kept).
    Io(std::io::Error),
    /// Not a regular file (a FIFO, socket or device): never read.
    NotRegular,
    /// Reached through a symbolic link leading out of the dataset: never opened.
    LeadsOut,
    /// Larger than the cap (`len` bytes, or more than `cap` read when it grew).
    TooLarge {
        /// Its size when opened, `None` when it grew while read.
        len: Option<u64>,
        /// The cap.
        cap: u64,
    },
}

impl std::fmt::Display for ReadError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            ReadError::Io(e) => write!(f, "cannot be read: {e}"),
            ReadError::NotRegular => {
                f.write_str("is not a regular file (a FIFO, socket or device); skipped")
            }
            ReadError::LeadsOut => f.write_str(
                "is reached through a symbolic link leading out of the dataset; not followed",
            ),
            ReadError::TooLarge {
                len: Some(len),
                cap,
            } => {
                write!(
                    f,
                    "is {len} bytes, over the {cap} bytes read of a dataset's file"
                )
            }
            ReadError::TooLarge { len: None, cap } => {
                write!(f, "grew over the {cap} bytes read of a dataset's file")
            }
        }
    }
}

impl std::error::Error for ReadError {}

impl ReadError {
    /// As an I/O error of the same message, keeping the kind of an OS error (a missing file
    /// stays `NotFound`).
    pub fn into_io(self) -> std::io::Error {
        match self {
            ReadError::Io(e) => std::io::Error::new(e.kind(), format!("cannot be read: {e}")),
            other => std::io::Error::other(other.to_string()),
        }
    }
}

/// The bytes of `path` if it is a regular file (checked on the open file: a FIFO or device is
/// never read, and never blocks), at most `cap` bytes. For a path already found by walking a
/// root with [`classify`].
pub fn read_regular(path: &Path, cap: u64) -> Result<Vec<u8>, ReadError> {
    use std::os::unix::fs::OpenOptionsExt;
    // Non-blocking: a FIFO swapped in after `classify` must not hang the command.
    let f = std::fs::OpenOptions::new()
        .read(true)
        .custom_flags(O_NONBLOCK)
        .open(path)
        .map_err(ReadError::Io)?;
    read_open(f, cap)
}

/// [`read_regular`] of a file already opened.
/// The length of the open file `f`: a regular file of at most `cap` bytes.
fn checked_len(f: &std::fs::File, cap: u64) -> Result<u64, ReadError> {
    let meta = f.metadata().map_err(ReadError::Io)?;
    if !meta.is_file() {
        return Err(ReadError::NotRegular);
    }
    if meta.len() > cap {
        let len = Some(meta.len());
        return Err(ReadError::TooLarge { len, cap });
    }
    Ok(meta.len())
}

fn read_open(f: std::fs::File, cap: u64) -> Result<Vec<u8>, ReadError> {
    let len = checked_len(&f, cap)?;
    let mut bytes = Vec::with_capacity(len as usize);
    f.take(cap + 1)
        .read_to_end(&mut bytes)
        .map_err(ReadError::Io)?;
    if bytes.len() as u64 > cap {
        return Err(ReadError::TooLarge { len: None, cap });
    }
    Ok(bytes)
}

/// Largest metadata file read (a sample's JSON is a few KB).
pub const MAX_METADATA_BYTES: u64 = 64 << 20;

/// Largest failure ledger read (one line per failed image).
pub const MAX_LEDGER_BYTES: u64 = 256 << 20;
