//! Reading a dataset folder someone else wrote (`verify`, `export`, `preview`, `report`,
//! `eval`): its files are data, not instructions. One place decides what is followed and what
//! is read:
//!
//! - a symbolic link is followed only when its target (resolved) lies inside the dataset's
//!   root; one that leads out of it is reported and never opened;
//! - only regular files are read: a FIFO, socket or device (also behind a link) is skipped
//!   without blocking (files are opened with `O_NONBLOCK` and checked with `fstat` before a
//!   byte is read);
//! - a file is read with a cap ([`MAX_FILE_BYTES`]), never to the end of whatever it holds.

use std::io::Read;
use std::path::{Path, PathBuf};

/// The largest file of a dataset that is read (1 GiB): far over any PNG of an
/// 8192 x 8192 image, any metadata or any manifest this tool writes.
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
/// not, in one line (a link out of the root, not a regular file, too large, unreadable).
pub fn read(root: &Path, path: &Path, cap: u64) -> Result<Vec<u8>, String> {
    if let Kind::Skipped(why) = classify(root, path) {
        return Err(why);
    }
    read_regular(path, cap)
}

/// The bytes of `path` if it is a regular file (checked on the open file: a FIFO or device is
/// never read, and never blocks), at most `cap` bytes; `Err` says why not, in one line. For a
/// path already found by walking a root with [`classify`].
pub fn read_regular(path: &Path, cap: u64) -> Result<Vec<u8>, String> {
    use std::os::unix::fs::OpenOptionsExt;
    // Non-blocking: a FIFO swapped in after `classify` must not hang the command.
    let f = std::fs::OpenOptions::new()
        .read(true)
        .custom_flags(O_NONBLOCK)
        .open(path)
        .map_err(|e| format!("cannot be read: {e}"))?;
    let meta = f.metadata().map_err(|e| format!("cannot be read: {e}"))?;
    if !meta.is_file() {
        return Err("is not a regular file (a FIFO, socket or device); skipped".into());
    }
    if meta.len() > cap {
        return Err(format!(
            "is {} bytes, over the {cap} bytes read of a dataset's file",
            meta.len()
        ));
    }
    let mut bytes = Vec::with_capacity(meta.len() as usize);
    f.take(cap + 1)
        .read_to_end(&mut bytes)
        .map_err(|e| format!("cannot be read: {e}"))?;
    if bytes.len() as u64 > cap {
        return Err(format!(
            "grew over the {cap} bytes read of a dataset's file"
        ));
    }
    Ok(bytes)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn links_out_and_fifos_are_not_read() {
        let dir = tempfile::tempdir().unwrap();
        let outside = tempfile::tempdir().unwrap();
        let data = dir.path().join("data");
        std::fs::create_dir(&data).unwrap();
        std::fs::write(outside.path().join("secret"), b"s").unwrap();
        std::fs::write(data.join("a.json"), b"{}").unwrap();
        std::os::unix::fs::symlink(outside.path().join("secret"), data.join("out.png")).unwrap();
        std::os::unix::fs::symlink(data.join("a.json"), data.join("in.json")).unwrap();
        std::os::unix::fs::symlink("/dev/zero", data.join("zero.png")).unwrap();
        let fifo = data.join("fifo.png");
        assert!(std::process::Command::new("mkfifo")
            .arg(&fifo)
            .status()
            .unwrap()
            .success());
        let root = root(&data).unwrap();
        assert_eq!(read(&root, &data.join("a.json"), 10).unwrap(), b"{}");
        assert_eq!(read(&root, &data.join("in.json"), 10).unwrap(), b"{}");
        assert!(read(&root, &data.join("out.png"), 10)
            .unwrap_err()
            .contains("leading out of the dataset"));
        assert!(read(&root, &data.join("zero.png"), 10)
            .unwrap_err()
            .contains("leading out of the dataset"));
        assert!(read(&root, &fifo, 10)
            .unwrap_err()
            .contains("not a regular file"));
        assert!(read(&root, &data.join("a.json"), 1)
            .unwrap_err()
            .contains("over the 1 bytes"));
    }
}
