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
//!
//! On top of that, the one read side of the layout ([`crate::layout`]): [`Dataset::open`]
//! walks a dataset once and finds its variant folders, samples ([`SampleRef`]: variant, index,
//! stem, folder, the files found; paths from the pass table), manifests, ledgers, temporaries
//! and what was not followed; [`MetadataView`] is the typed, bounded view of a sample's
//! metadata (errors name the file and the key); the manifests' union is
//! [`crate::manifest::union`]. No other module walks a dataset folder or parses a stem.

use std::collections::{BTreeMap, BTreeSet};
use std::io::Read;
use std::path::{Path, PathBuf};

use serde_json::Value;

use crate::layout;
use crate::manifest::Manifest;
use clevrtex_scene::scene_file::MAX_IMAGE_SIDE;
use clevrtex_scene::Pass;

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

/// Why the PNG `bytes` of a sample's `pass` are not of the mode every reader takes for it,
/// from the header alone (before any decoder allocates), or `None` when they are, or when
/// they are no PNG at all (the decoder then says so). The mask must be 8-bit object ids, one
/// channel: a palette index as clevrtex and the public ClevrTex write it, or greyscale (an RGB
/// `_flat.png` would be read as three ids a pixel, a 16-bit one as ids past 255); the other
/// passes must have their pass-table mode ([`clevrtex_scene::passes::PngKind`]). Used by `verify`,
/// `preview`, `report`, `materials measure`, `eval`'s ground truth and the Python `Dataset`.
pub fn png_mode_problem(bytes: &[u8], pass: Pass) -> Option<String> {
    use clevrtex_scene::passes::PngKind;
    if bytes.len() < 26 || &bytes[..8] != b"\x89PNG\r\n\x1a\n" || &bytes[12..16] != b"IHDR" {
        return None;
    }
    let (depth, colour) = (bytes[24], bytes[25]);
    let mode = |depth: u8, colour: u8| {
        let c = match colour {
            0 => "greyscale",
            2 => "RGB",
            3 => "palette",
            4 => "greyscale-alpha",
            6 => "RGBA",
            _ => "unknown-colour",
        };
        format!("{depth}-bit {c}")
    };
    let ok = match pass.spec().png {
        PngKind::Palette8 | PngKind::Gray8 if pass == Pass::Mask => {
            depth == 8 && (colour == 0 || colour == 3)
        }
        PngKind::Palette8 => (depth, colour) == (8, 3),
        PngKind::Gray8 => (depth, colour) == (8, 0),
        PngKind::Rgb8 => (depth, colour) == (8, 2),
        PngKind::Gray16 => (depth, colour) == (16, 0),
        PngKind::Rgb16 => (depth, colour) == (16, 2),
    };
    if ok {
        return None;
    }
    let want = match pass.spec().png {
        _ if pass == Pass::Mask => "8-bit palette or greyscale object ids".to_string(),
        PngKind::Palette8 => mode(8, 3),
        PngKind::Gray8 => mode(8, 0),
        PngKind::Rgb8 => mode(8, 2),
        PngKind::Gray16 => mode(16, 0),
        PngKind::Rgb16 => mode(16, 2),
    };
    Some(format!(
        "is a {} PNG, but a {} pass must be {want}",
        mode(depth, colour),
        pass.name()
    ))
}

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
    read_open(std::fs::File::from(fd), cap)
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
fn read_open(f: std::fs::File, cap: u64) -> Result<Vec<u8>, ReadError> {
    let meta = f.metadata().map_err(ReadError::Io)?;
    if !meta.is_file() {
        return Err(ReadError::NotRegular);
    }
    if meta.len() > cap {
        let len = Some(meta.len());
        return Err(ReadError::TooLarge { len, cap });
    }
    let mut bytes = Vec::with_capacity(meta.len() as usize);
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

/// Why a dataset cannot be opened at all (what is wrong inside it is recorded, not an error).
#[derive(Debug, thiserror::Error)]
pub enum DatasetError {
    /// The path given is not a folder.
    #[error("`{}` is not a folder", .path.display())]
    NotAFolder {
        /// The path given.
        path: PathBuf,
    },
    /// The folder given cannot be resolved or listed.
    #[error("`{}` cannot be read: {cause}", .path.display())]
    Unreadable {
        /// The path given.
        path: PathBuf,
        /// Why.
        cause: std::io::Error,
    },
}

/// An entry of the dataset that was not followed or not read.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Skip {
    /// Its path.
    pub path: PathBuf,
    /// Why, one line (`is a symbolic link leading out of the dataset ...`).
    pub why: String,
    /// The stem of the sample it belongs to, when its name is one of the layout's files.
    pub stem: Option<String>,
}

impl std::fmt::Display for Skip {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "`{}` {}", self.path.display(), self.why)
    }
}

/// One sample found: the regular files of its stem in one folder.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct SampleRef {
    /// The variant its stem names.
    pub variant: String,
    /// Its index.
    pub index: u64,
    /// Its stem, `CLEVRTEX_<variant>_<index:06>`.
    pub stem: String,
    /// The folder it was found in.
    pub dir: PathBuf,
    /// The names of its regular files in `dir` (files of the layout only; links inside the
    /// dataset included).
    pub files: BTreeSet<String>,
}

impl SampleRef {
    /// The path of the file `name` in the sample's folder.
    pub fn path(&self, name: &str) -> PathBuf {
        self.dir.join(name)
    }

    /// The path of `pass`'s file (from the pass table), whether it exists or not.
    pub fn pass_path(&self, pass: Pass) -> PathBuf {
        self.path(&layout::pass_file(&self.stem, pass))
    }

    /// Whether `pass`'s file was found, a regular file.
    pub fn has_pass(&self, pass: Pass) -> bool {
        self.files.contains(&layout::pass_file(&self.stem, pass))
    }

    /// The metadata's file name.
    pub fn metadata_name(&self) -> String {
        layout::metadata_file(&self.stem)
    }

    /// The path of the metadata.
    pub fn metadata_path(&self) -> PathBuf {
        self.path(&self.metadata_name())
    }

    /// Whether the metadata was found, a regular file.
    pub fn has_metadata(&self) -> bool {
        self.files.contains(&self.metadata_name())
    }

    /// The split the layout's position rule gives the sample in a run of `total` images (what
    /// `generate` records; `verify` checks the recorded split against it).
    pub fn rule_split(&self, total: u64) -> layout::Split {
        layout::Split::of(layout::variant_splits(&self.variant), self.index, total)
    }
}

/// One `clevrtex_<variant>` folder and what was found in it.
#[derive(Debug, Clone, Default)]
pub struct VariantDir {
    /// The variant its name says.
    pub variant: String,
    /// The folder (under the path given).
    pub dir: PathBuf,
    /// The folder its runs wrote into (`--out`): the path given, or its parent when the path
    /// given is the variant folder.
    pub out: PathBuf,
    /// Samples in walk order (sample folders by name, stems by name); an index may be found
    /// in more than one folder.
    pub samples: Vec<SampleRef>,
    /// Run manifests (`MANIFEST-*.json`), regular files.
    pub manifests: Vec<PathBuf>,
    /// Failure ledgers ([`layout::LEDGER_FILE`]).
    pub ledgers: Vec<PathBuf>,
    /// Temporary files of writers (`*.clevrtex-tmp`, `.*.tmp*` in sample folders).
    pub temp_files: Vec<PathBuf>,
    /// Entries not followed or not read, in walk order: links out of the dataset, FIFOs,
    /// devices, folders named like a sample's file, folders that cannot be listed.
    pub skipped: Vec<Skip>,
    /// Folders that cannot be listed (this one or a sample folder), with the error.
    pub unreadable: Vec<(PathBuf, String)>,
    /// Regular files and folders that are not the layout's (stray names).
    pub strays: Vec<PathBuf>,
    /// Files named like a sample's that lie in the variant folder itself, outside every
    /// sample folder: not a sample of the layout, but the public loader's `**/` glob reads
    /// them as one (a second copy when the sample is also in its folder). `verify` names them.
    pub misplaced: Vec<PathBuf>,
}

impl VariantDir {
    /// The entries not followed that are not a sample's file, or are a sample's metadata:
    /// what the readers of metadata report (a pass's link or FIFO is reported by who reads
    /// the pass).
    pub fn skipped_for_metadata(&self) -> impl Iterator<Item = &Skip> {
        self.skipped.iter().filter(|s| match &s.stem {
            None => true,
            Some(stem) => s
                .path
                .file_name()
                .is_some_and(|n| n.to_string_lossy() == layout::metadata_file(stem)),
        })
    }

    /// The manifests read ([`Manifest::read`]): (path, manifest or why not).
    pub fn read_manifests(&self) -> Vec<(PathBuf, Result<Manifest, String>)> {
        self.manifests
            .iter()
            .map(|p| (p.clone(), Manifest::read(p)))
            .collect()
    }
}

/// A dataset folder opened: one walk, nothing read but folder listings. The one place that
/// walks a dataset, recognises its stems and builds its files' paths (`verify`, `export`,
/// `preview`, `report`, `eval`'s ground truth and the Python `Dataset` use it).
#[derive(Debug, Clone)]
pub struct Dataset {
    /// The path given.
    pub given: PathBuf,
    /// Its canonical form, which no link may leave.
    pub root: PathBuf,
    /// Whether the path given is itself a `clevrtex_<variant>` folder.
    pub is_variant_dir: bool,
    /// The variant folders, by name.
    pub variants: Vec<VariantDir>,
    /// Entries named `clevrtex_<variant>` that were not followed: (variant, why).
    pub skipped: Vec<(String, Skip)>,
}

/// One line of a failure ledger.
#[derive(Debug, Clone, PartialEq)]
pub struct LedgerEntry {
    /// `variant`, when a string.
    pub variant: Option<String>,
    /// `index`, when a whole number.
    pub index: Option<u64>,
    /// `error`, when a string (else empty).
    pub error: String,
}

impl Dataset {
    /// Open the dataset at `path` (trusted: the command line's): an output folder of
    /// `clevrtex generate` (its `clevrtex_<variant>` folders), or one variant folder.
    pub fn open(path: &Path) -> Result<Dataset, DatasetError> {
        if !path.is_dir() {
            return Err(DatasetError::NotAFolder {
                path: path.to_path_buf(),
            });
        }
        let unreadable = |cause| DatasetError::Unreadable {
            path: path.to_path_buf(),
            cause,
        };
        let root = root(path).map_err(unreadable)?;
        let name = root
            .file_name()
            .map(|n| n.to_string_lossy().into_owned())
            .unwrap_or_default();
        let mut ds = Dataset {
            given: path.to_path_buf(),
            root: root.clone(),
            is_variant_dir: false,
            variants: Vec::new(),
            skipped: Vec::new(),
        };
        if let Some(v) = name.strip_prefix("clevrtex_") {
            ds.is_variant_dir = true;
            let out = path.parent().unwrap_or(Path::new(".")).to_path_buf();
            ds.variants.push(walk_variant(&root, v, path, out));
            return Ok(ds);
        }
        for (name, p, kind) in list(&root, path).map_err(unreadable)? {
            let Some(v) = name.strip_prefix("clevrtex_") else {
                continue;
            };
            // `clevrtex_` followed by no variant name (or one no run could have written) is
            // named, not passed over: its samples would go unchecked.
            if let Some(why) = clevrtex_scene::names::variant_name_problem(v) {
                ds.skipped.push((
                    v.to_string(),
                    Skip {
                        path: p,
                        why: format!("is not a variant folder: the name after `clevrtex_` {why}"),
                        stem: None,
                    },
                ));
                continue;
            }
            match kind {
                Kind::Dir => ds
                    .variants
                    .push(walk_variant(&root, v, &p, path.to_path_buf())),
                Kind::Skipped(why) => ds.skipped.push((
                    v.to_string(),
                    Skip {
                        path: p,
                        why,
                        stem: None,
                    },
                )),
                Kind::File => {}
            }
        }
        Ok(ds)
    }

    /// The bytes of `path` (a file found in this dataset), at most `cap`; `Err` says why not.
    pub fn read(&self, path: &Path, cap: u64) -> Result<Vec<u8>, String> {
        read(&self.root, path, cap)
    }

    /// What `path` (under this dataset) is, links resolved only inside the root.
    pub fn classify(&self, path: &Path) -> Kind {
        classify(&self.root, path)
    }

    /// A sample's metadata: read up to [`MAX_METADATA_BYTES`] and parsed as JSON; `Err`
    /// says why not, in one line, without the path.
    pub fn read_metadata(&self, s: &SampleRef) -> Result<Value, String> {
        let bytes = self.read(&s.metadata_path(), MAX_METADATA_BYTES)?;
        serde_json::from_slice(&bytes).map_err(|e| format!("is not valid metadata: {e}"))
    }

    /// The lines of a failure ledger (read up to [`MAX_LEDGER_BYTES`]) that are JSON.
    pub fn read_ledger(&self, path: &Path) -> Result<Vec<LedgerEntry>, String> {
        let bytes = self.read(path, MAX_LEDGER_BYTES)?;
        Ok(String::from_utf8_lossy(&bytes)
            .lines()
            .filter_map(|l| serde_json::from_str::<Value>(l).ok())
            .map(|v| LedgerEntry {
                variant: v["variant"].as_str().map(str::to_string),
                index: v["index"].as_u64(),
                error: v["error"].as_str().unwrap_or("").to_string(),
            })
            .collect())
    }
}

/// The run manifests of the dataset at `out` (an output folder of `clevrtex generate`), by
/// variant folder name order: `(variant, path)`. Lists only `out` and its `clevrtex_<variant>`
/// folders (never a sample folder: cheap on any dataset), with the same rules as
/// [`Dataset::open`] (no link out of `out` followed, only regular files).
pub fn manifests_in(out: &Path) -> std::io::Result<Vec<(String, PathBuf)>> {
    let root = root(out)?;
    let mut found = Vec::new();
    for (name, p, kind) in list(&root, out)? {
        let Some(v) = name.strip_prefix("clevrtex_") else {
            continue;
        };
        if kind != Kind::Dir || clevrtex_scene::names::variant_name_problem(v).is_some() {
            continue;
        }
        let Ok(entries) = list(&root, &p) else {
            continue;
        };
        for (name, m, kind) in entries {
            if kind == Kind::File && crate::manifest::is_manifest_name(&name) {
                found.push((v.to_string(), m));
            }
        }
    }
    Ok(found)
}

/// Walk one variant folder: its sample folders, manifests, ledgers and temporaries.
fn walk_variant(root: &Path, variant: &str, dir: &Path, out: PathBuf) -> VariantDir {
    let mut vd = VariantDir {
        variant: variant.to_string(),
        dir: dir.to_path_buf(),
        out,
        ..VariantDir::default()
    };
    let entries = match list(root, dir) {
        Ok(e) => e,
        Err(e) => {
            vd.cannot_list(dir, e);
            return vd;
        }
    };
    for (name, p, kind) in entries {
        if name.ends_with(layout::TMP_SUFFIX) {
            vd.temp_files.push(p);
            continue;
        }
        match kind {
            Kind::Skipped(why) => vd.skipped.push(Skip {
                path: p,
                why,
                stem: None,
            }),
            Kind::Dir => walk_sample_dir(root, &p, &mut vd),
            Kind::File if crate::manifest::is_manifest_name(&name) => vd.manifests.push(p),
            Kind::File if name == layout::LEDGER_FILE => vd.ledgers.push(p),
            Kind::File if layout::parse_file_name(&name).is_some() => vd.misplaced.push(p),
            Kind::File => vd.strays.push(p),
        }
    }
    vd
}

impl VariantDir {
    fn cannot_list(&mut self, dir: &Path, e: std::io::Error) {
        self.skipped.push(Skip {
            path: dir.to_path_buf(),
            why: format!("cannot be read: {e}"),
            stem: None,
        });
        self.unreadable.push((dir.to_path_buf(), e.to_string()));
    }
}

/// Collect the samples, temporaries and skipped entries of one sample folder.
fn walk_sample_dir(root: &Path, dir: &Path, vd: &mut VariantDir) {
    let entries = match list(root, dir) {
        Ok(e) => e,
        Err(e) => {
            vd.cannot_list(dir, e);
            return;
        }
    };
    let mut by_stem: BTreeMap<String, SampleRef> = BTreeMap::new();
    for (name, p, kind) in entries {
        if name.ends_with(layout::TMP_SUFFIX) || (name.starts_with('.') && name.contains(".tmp")) {
            vd.temp_files.push(p);
            continue;
        }
        let Some((stem, variant, index)) = layout::parse_file_name(&name) else {
            vd.strays.push(p);
            continue;
        };
        let why = match kind {
            Kind::File => {
                by_stem
                    .entry(stem.to_string())
                    .or_insert_with(|| SampleRef {
                        variant: variant.to_string(),
                        index,
                        stem: stem.to_string(),
                        dir: dir.to_path_buf(),
                        files: BTreeSet::new(),
                    })
                    .files
                    .insert(name.clone());
                continue;
            }
            Kind::Skipped(why) => why,
            Kind::Dir => "is a folder named like a file".to_string(),
        };
        vd.skipped.push(Skip {
            path: p,
            why,
            stem: Some(stem.to_string()),
        });
    }
    vd.samples.extend(by_stem.into_values());
}

/// A value of a sample's metadata that is not what a reader needs: the file and the key.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("metadata `{file}` key `{key}` {what}")]
pub struct MetadataError {
    /// The metadata file, as the caller names it.
    pub file: String,
    /// The key (dotted, `objects[i].visible_pixels` for a list's entry).
    pub key: String,
    /// What is wrong (`is "x", not a whole number from 1 to 4096`).
    pub what: String,
}

/// A metadata value for a message: its JSON, cut at 80 characters.
pub fn short(v: &Value) -> String {
    let t = v.to_string();
    if t.chars().count() > 80 {
        format!("{}...", t.chars().take(80).collect::<String>())
    } else {
        t
    }
}

/// The values of a sample's metadata that size or index something, typed and bounded before
/// anything is sized by them: the image's size (at most [`MAX_IMAGE_SIDE`] a side), the
/// objects (at most 255, a list as long as `num_objects`), the visibility threshold and each
/// object's visible pixels (at most the image's pixels), the passes listed; and the run's
/// `config_hash` (a string when present) that `verify` compares with the manifest.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct MetadataView {
    /// `render.width`.
    pub width: u32,
    /// `render.height`.
    pub height: u32,
    /// `num_objects`.
    pub num_objects: usize,
    /// `visibility_threshold_px` (0 when absent: the published data has none).
    pub visibility_threshold_px: u64,
    /// Each object's `visible_pixels`, when present.
    pub visible_pixels: Vec<Option<u64>>,
    /// `image_index`, when a whole number.
    pub image_index: Option<u64>,
    /// The passes the metadata's `passes` names (unknown names left out).
    pub passes: Vec<Pass>,
    /// `config_hash`: the config hash of the `generate` run that made the sample (absent:
    /// `None`, in older datasets, the published data and `render`'s samples).
    pub config_hash: Option<String>,
}

/// A whole number from the metadata at `key` (dotted), within `lo..=hi`.
pub fn meta_int(
    meta: &Value,
    file: &str,
    key: &str,
    lo: u64,
    hi: u64,
) -> Result<u64, MetadataError> {
    let v = key.split('.').fold(meta, |v, k| &v[k]);
    match v.as_u64() {
        Some(n) if (lo..=hi).contains(&n) => Ok(n),
        _ => Err(MetadataError {
            file: file.to_string(),
            key: key.to_string(),
            what: format!("is {v}, not a whole number from {lo} to {hi}"),
        }),
    }
}

impl MetadataView {
    /// The typed view of `meta` (a JSON object) of the file `file`; the error names the key.
    pub fn of(meta: &Value, file: &str) -> Result<MetadataView, MetadataError> {
        let err = |key: &str, what: String| MetadataError {
            file: file.to_string(),
            key: key.to_string(),
            what,
        };
        let side = u64::from(MAX_IMAGE_SIDE);
        let width = meta_int(meta, file, "render.width", 1, side)? as u32;
        let height = meta_int(meta, file, "render.height", 1, side)? as u32;
        let pixels = u64::from(width) * u64::from(height);
        let n = meta_int(meta, file, "num_objects", 0, 255)? as usize;
        // The split names a folder or shard in `export` and a report row: `../x` is refused by
        // every reader alike (`verify` passed it while `export` refused it).
        check_split(meta, file)?;
        let config_hash = match meta.get("config_hash") {
            None => None,
            Some(Value::String(h)) => Some(h.clone()),
            Some(v) => return Err(err("config_hash", format!("is {}, not a string", short(v)))),
        };
        let threshold = match meta.get("visibility_threshold_px") {
            None => 0,
            Some(_) => meta_int(meta, file, "visibility_threshold_px", 0, pixels)?,
        };
        let Some(objects) = meta["objects"].as_array() else {
            return Err(err(
                "objects",
                format!("is {}, not a list", short(&meta["objects"])),
            ));
        };
        if objects.len() != n {
            return Err(err(
                "objects",
                format!("has {} entries but `num_objects` is {n}", objects.len()),
            ));
        }
        let mut visible = Vec::with_capacity(n);
        for (i, o) in objects.iter().enumerate() {
            visible.push(match o.get("visible_pixels") {
                None => None,
                Some(v) => match v.as_u64() {
                    Some(p) if p <= pixels => Some(p),
                    _ => {
                        return Err(err(
                            &format!("objects[{i}].visible_pixels"),
                            format!(
                                "is {}, not a whole number from 0 to the image's {pixels} pixels",
                                short(v)
                            ),
                        ))
                    }
                },
            });
        }
        Ok(MetadataView {
            width,
            height,
            num_objects: n,
            visibility_threshold_px: threshold,
            visible_pixels: visible,
            image_index: meta["image_index"].as_u64(),
            passes: meta["passes"]
                .as_object()
                .map(|m| m.keys().filter_map(|k| Pass::from_name(k)).collect())
                .unwrap_or_default(),
            config_hash,
        })
    }
}

/// The check every reader that shows or measures a sample applies to its metadata (`preview`,
/// `report`): a JSON object; ours (with `render`) must give a whole [`MetadataView`]; the
/// downloaded ClevrTex's (no `render`) must type its keys that are there (`objects` a list,
/// `num_objects` 0 to 255 and equal to its length). The error names the file and key.
pub fn check_metadata(meta: &Value, file: &str) -> Result<(), MetadataError> {
    let err = |key: &str, what: String| MetadataError {
        file: file.to_string(),
        key: key.to_string(),
        what,
    };
    if !meta.is_object() {
        return Err(err(
            "(top level)",
            format!("is {}, not an object", short(meta)),
        ));
    }
    if meta.get("render").is_some() {
        return MetadataView::of(meta, file).map(|_| ());
    }
    let objects = match meta.get("objects") {
        None => None,
        Some(Value::Array(a)) => Some(a.len()),
        Some(v) => return Err(err("objects", format!("is {}, not a list", short(v)))),
    };
    check_split(meta, file)?;
    if meta.get("num_objects").is_some() {
        let n = meta_int(meta, file, "num_objects", 0, 255)? as usize;
        if objects.is_some_and(|len| len != n) {
            return Err(err(
                "objects",
                format!(
                    "has {} entries but `num_objects` is {n}",
                    objects.unwrap_or(0)
                ),
            ));
        }
    }
    Ok(())
}

/// The passes whose `*_filename` key ([`Pass::metadata_key`], the pass table's) the metadata `meta` of
/// `stem` sets, in pass-table order: each must name the layout's file (or be null, absent:
/// not written). File names come from the layout, never from the metadata.
pub fn listed_passes(meta: &Value, file: &str, stem: &str) -> Result<Vec<Pass>, MetadataError> {
    let mut out = Vec::new();
    for pass in Pass::ALL {
        let key = pass.metadata_key();
        let want = layout::pass_file(stem, pass);
        match &meta[key] {
            Value::Null => {}
            Value::String(name) if *name == want => out.push(pass),
            other => {
                return Err(MetadataError {
                    file: file.to_string(),
                    key: key.to_string(),
                    what: format!("is {other}, not the layout's `{want}` (or null)"),
                })
            }
        }
    }
    Ok(out)
}

/// The metadata's `split`, checked without knowing the variant: `test`, `val`, `train`, none,
/// or (the public generator records its variant there) a name a variant may have; anything
/// else (`../x`) is refused by every reader alike. [`recorded_split`] then reads it.
fn check_split(meta: &Value, file: &str) -> Result<(), MetadataError> {
    match &meta["split"] {
        Value::String(s) if clevrtex_scene::names::variant_name_problem(s).is_none() => Ok(()),
        split => recorded_split(split, "", file).map(|_| ()),
    }
}

/// The split a sample's metadata records in `split`: `Some` for `test`, `val` or `train`;
/// `None` where it records none: `split` absent, or the name of the sample's `variant` (the
/// public generator, karazijal/clevrtex-generation, writes the variant there, so the published
/// ClevrTex is split by position: [`splits`]). Anything else is an error naming the file and
/// the key.
pub fn recorded_split(
    split: &Value,
    variant: &str,
    file: &str,
) -> Result<Option<layout::Split>, MetadataError> {
    let err = |what: String| MetadataError {
        file: file.to_string(),
        key: "split".into(),
        what,
    };
    match split {
        Value::Null => Ok(None),
        Value::String(s) if s == variant => Ok(None),
        Value::String(s) => layout::Split::parse(s).map(Some).ok_or_else(|| {
            err(format!(
                "is `{}`, not test, val or train",
                clevrtex_scene::text::printable(s)
            ))
        }),
        other => Err(err(format!("is {}, not test, val or train", short(other)))),
    }
}

/// The split of each sample of one variant, the samples given in index order with the split
/// each records ([`recorded_split`]): the one rule every reader follows (`Dataset`, `eval`,
/// `export`, `verify`, `report`). The recorded split is authoritative: `generate` fixes it from
/// `--total` and a dataset grown with `--start` keeps it. A sample that records none (the
/// published ClevrTex) gets the public loader's position rule among the samples given (test the
/// first `int(0.1 N)`, val up to `int(0.2 N)`, train the rest; a test-only variant all test).
pub fn splits(variant: &str, recorded: &[Option<layout::Split>]) -> Vec<layout::Split> {
    let rule = layout::variant_splits(variant);
    let n = recorded.len() as u64;
    recorded
        .iter()
        .enumerate()
        .map(|(i, r)| r.unwrap_or_else(|| layout::Split::of(rule, i as u64, n)))
        .collect()
}

/// How many of `splits` are in each split, for messages: `test 0, val 0, train 4`.
pub fn split_sizes(splits: &[layout::Split]) -> String {
    layout::Split::ALL
        .iter()
        .map(|s| format!("{} {}", s.name(), splits.iter().filter(|x| *x == s).count()))
        .collect::<Vec<_>>()
        .join(", ")
}

/// Only the `split` of a sample's metadata (the rest skipped unparsed, so reading the splits
/// of a large dataset costs little more than listing it).
#[derive(serde::Deserialize)]
struct SplitOnly {
    #[serde(default)]
    split: Value,
}

/// The split the metadata file `path` (of a sample of `variant`, in the dataset whose
/// canonical root is `root`) records ([`recorded_split`]), reading only that key; `Err` says
/// why not in one line, without the path (unreadable, not JSON, a bad `split`).
pub fn read_recorded_split(
    root: &Path,
    path: &Path,
    variant: &str,
) -> Result<Option<layout::Split>, String> {
    let bytes = read(root, path, MAX_METADATA_BYTES)?;
    let only: SplitOnly =
        serde_json::from_slice(&bytes).map_err(|e| format!("is not valid metadata: {e}"))?;
    recorded_split(&only.split, variant, "").map_err(|e| format!("key `split` {}", e.what))
}

impl Dataset {
    /// The split sample `s`'s metadata records ([`read_recorded_split`]).
    pub fn read_recorded_split(&self, s: &SampleRef) -> Result<Option<layout::Split>, String> {
        read_recorded_split(&self.root, &s.metadata_path(), &s.variant)
    }
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

    fn mkfifo(p: &Path) {
        assert!(std::process::Command::new("mkfifo")
            .arg(p)
            .status()
            .unwrap()
            .success());
    }

    #[test]
    fn open_finds_samples_and_what_does_not_belong() {
        let dir = tempfile::tempdir().unwrap();
        let outside = tempfile::tempdir().unwrap();
        std::fs::write(outside.path().join("secret.json"), b"{}").unwrap();
        let out = dir.path().join("out");
        let v = out.join("clevrtex_camo");
        let s0 = v.join("0");
        std::fs::create_dir_all(&s0).unwrap();
        let stem = layout::stem("camo", 3);
        for pass in [Pass::Rgb, Pass::Mask] {
            std::fs::write(s0.join(layout::pass_file(&stem, pass)), b"png").unwrap();
        }
        std::fs::write(s0.join(layout::metadata_file(&stem)), b"{}").unwrap();
        // A sample whose metadata leads out of the dataset, one whose mask is a FIFO.
        let out_stem = layout::stem("camo", 4);
        std::fs::write(s0.join(layout::pass_file(&out_stem, Pass::Rgb)), b"png").unwrap();
        std::os::unix::fs::symlink(
            outside.path().join("secret.json"),
            s0.join(layout::metadata_file(&out_stem)),
        )
        .unwrap();
        mkfifo(&s0.join(layout::pass_file(&stem, Pass::Depth)));
        std::fs::write(s0.join("notes.txt"), b"x").unwrap();
        std::fs::write(s0.join(".CLEVRTEX_camo_000005.png.tmp1"), b"x").unwrap();
        std::fs::create_dir(s0.join(layout::pass_file(&layout::stem("camo", 6), Pass::Albedo)))
            .unwrap();
        std::fs::write(v.join("MANIFEST-0-8-0of1.json"), b"not json").unwrap();
        std::fs::write(
            v.join(layout::LEDGER_FILE),
            b"{\"variant\":\"camo\",\"index\":7,\"error\":\"boom\"}\nnot json\n",
        )
        .unwrap();
        std::fs::write(v.join("x.clevrtex-tmp"), b"").unwrap();
        std::fs::write(v.join("README"), b"").unwrap();
        std::os::unix::fs::symlink(outside.path(), out.join("clevrtex_away")).unwrap();
        // A copy of a sample at the variant root (issue 34: the public loader's `**/` glob
        // reads it a second time; `verify` ignored it).
        std::fs::write(v.join(layout::metadata_file(&stem)), b"{}").unwrap();

        let ds = Dataset::open(&out).unwrap();
        assert!(!ds.is_variant_dir);
        assert_eq!(ds.variants.len(), 1);
        assert_eq!(ds.skipped.len(), 1);
        assert_eq!(ds.skipped[0].0, "away");
        assert!(ds.skipped[0].1.why.contains("leading out of the dataset"));
        let vd = &ds.variants[0];
        assert_eq!(
            (vd.variant.as_str(), vd.out.as_path()),
            ("camo", out.as_path())
        );
        let found: Vec<(u64, usize)> = vd
            .samples
            .iter()
            .map(|s| (s.index, s.files.len()))
            .collect();
        assert_eq!(found, [(3, 3), (4, 1)]);
        let s3 = &vd.samples[0];
        assert!(s3.has_pass(Pass::Mask) && s3.has_metadata() && !s3.has_pass(Pass::Depth));
        assert_eq!(
            s3.pass_path(Pass::Mask),
            s0.join(format!("{stem}_flat.png"))
        );
        assert!(!vd.samples[1].has_metadata());
        let skipped: Vec<String> = vd.skipped.iter().map(ToString::to_string).collect();
        assert_eq!(skipped.len(), 3, "{skipped:?}");
        assert!(skipped
            .iter()
            .any(|l| l.contains("_000004.json` is a symbolic link leading out")));
        assert!(skipped
            .iter()
            .any(|l| l.contains("_000003_depth_0001.png` is not a regular file")));
        assert!(skipped
            .iter()
            .any(|l| l.contains("is a folder named like a file")));
        // Metadata readers report the metadata's link, not the FIFO pass.
        assert_eq!(vd.skipped_for_metadata().count(), 1);
        assert_eq!(vd.temp_files.len(), 2);
        assert_eq!(vd.strays, [s0.join("notes.txt"), v.join("README")]);
        assert_eq!(vd.misplaced, [v.join(layout::metadata_file(&stem))]);
        assert_eq!(vd.manifests, [v.join("MANIFEST-0-8-0of1.json")]);
        assert!(vd.read_manifests()[0].1.is_err());
        let ledger = ds.read_ledger(&vd.ledgers[0]).unwrap();
        assert_eq!(ledger.len(), 1);
        assert_eq!(
            (ledger[0].index, ledger[0].error.as_str()),
            (Some(7), "boom")
        );
        assert_eq!(ds.read_metadata(s3).unwrap(), serde_json::json!({}));

        // The variant folder itself: its runs wrote into its parent.
        let one = Dataset::open(&v).unwrap();
        assert!(one.is_variant_dir);
        assert_eq!(one.variants[0].out, out);
        assert_eq!(one.variants[0].samples.len(), 2);
        assert!(matches!(
            Dataset::open(&s0.join("notes.txt")),
            Err(DatasetError::NotAFolder { .. })
        ));
    }

    #[test]
    fn metadata_view_bounds_counts_and_names_file_and_key() {
        let good = serde_json::json!({
            "render": {"width": 4, "height": 2},
            "num_objects": 1,
            "visibility_threshold_px": 1,
            "objects": [{"visible_pixels": 3}],
            "image_index": 9,
            "passes": {"rgb": {}, "mask": {}, "nope": {}},
        });
        let v = MetadataView::of(&good, "m.json").unwrap();
        assert_eq!((v.width, v.height, v.num_objects), (4, 2, 1));
        assert_eq!(v.visible_pixels, [Some(3)]);
        assert_eq!(v.image_index, Some(9));
        assert_eq!(v.passes.len(), 2);
        assert_eq!(v.config_hash, None, "absent: not compared");
        let mut hashed = good.clone();
        hashed["config_hash"] = "00ff".into();
        assert_eq!(
            MetadataView::of(&hashed, "m.json")
                .unwrap()
                .config_hash
                .as_deref(),
            Some("00ff")
        );
        let bad = |patch: serde_json::Value| {
            let mut m = good.clone();
            for (k, val) in patch.as_object().unwrap() {
                m[k] = val.clone();
            }
            MetadataView::of(&m, "m.json").unwrap_err()
        };
        let e = bad(serde_json::json!({"render": {"width": "4", "height": 2}}));
        assert_eq!(
            (e.file.as_str(), e.key.as_str()),
            ("m.json", "render.width")
        );
        assert_eq!(
            e.to_string(),
            "metadata `m.json` key `render.width` is \"4\", not a whole number from 1 to 4096"
        );
        assert_eq!(
            bad(serde_json::json!({"render": {"width": 4, "height": 1u64 << 40}})).key,
            "render.height"
        );
        assert_eq!(
            bad(serde_json::json!({"num_objects": 1u64 << 62})).key,
            "num_objects"
        );
        assert_eq!(bad(serde_json::json!({"num_objects": 2})).key, "objects");
        assert_eq!(
            bad(serde_json::json!({"config_hash": 7})).key,
            "config_hash"
        );
        assert_eq!(bad(serde_json::json!({"objects": {"a": 1}})).key, "objects");
        assert_eq!(
            bad(serde_json::json!({"objects": [{"visible_pixels": 9}]})).key,
            "objects[0].visible_pixels"
        );
        assert_eq!(
            bad(serde_json::json!({"visibility_threshold_px": -1})).key,
            "visibility_threshold_px"
        );

        let stem = "CLEVRTEX_camo_000001";
        let meta =
            serde_json::json!({"image_filename": "CLEVRTEX_camo_000001.png", "split": "val"});
        assert_eq!(listed_passes(&meta, "m", stem).unwrap(), [Pass::Rgb]);
        assert_eq!(
            recorded_split(&meta["split"], "camo", "m").unwrap(),
            Some(layout::Split::Val)
        );
        // Absent, or the variant's name (the public generator's metadata): none recorded.
        assert_eq!(recorded_split(&Value::Null, "camo", "m").unwrap(), None);
        assert_eq!(recorded_split(&"camo".into(), "camo", "m").unwrap(), None);
        assert_eq!(
            recorded_split(&"full".into(), "camo", "m").unwrap_err().key,
            "split"
        );
        let e = listed_passes(
            &serde_json::json!({"mask_filename": "../../etc/passwd"}),
            "m",
            stem,
        )
        .unwrap_err();
        assert_eq!(e.key, "mask_filename");
        assert_eq!(
            recorded_split(&serde_json::json!(3), "camo", "m")
                .unwrap_err()
                .key,
            "split"
        );
    }

    #[test]
    fn a_split_that_is_no_split_is_refused_by_every_reader() {
        let ours = serde_json::json!({
            "render": {"width": 4, "height": 3}, "num_objects": 0, "objects": [],
            "split": "../x",
        });
        let e = MetadataView::of(&ours, "m.json").unwrap_err().to_string();
        assert!(e.contains("split") && e.contains("../x"), "{e}");
        let published = serde_json::json!({"objects": [], "split": "../x"});
        let e = check_metadata(&published, "m.json")
            .unwrap_err()
            .to_string();
        assert!(e.contains("split") && e.contains("../x"), "{e}");
    }

    /// A bucket folder swapped for a link out of the dataset after the walk is not read
    /// through (before, only the last component was checked: the Python `Dataset` and every
    /// reader read the canary's file); links inside the dataset still are.
    #[test]
    fn a_folder_swapped_for_a_link_out_is_not_read_through() {
        let data = tempfile::tempdir().unwrap();
        let canary = tempfile::tempdir().unwrap();
        let v = data.path().join("clevrtex_camo");
        let bucket = v.join("0");
        std::fs::create_dir_all(&bucket).unwrap();
        let stem = layout::stem("camo", 0);
        let meta = layout::metadata_file(&stem);
        std::fs::write(bucket.join(&meta), b"{}").unwrap();
        std::fs::write(canary.path().join(&meta), b"secret").unwrap();
        let ds = Dataset::open(data.path()).unwrap();
        let s = &ds.variants[0].samples[0];
        assert_eq!(ds.read(&s.metadata_path(), 100).unwrap(), b"{}");
        // A link inside the dataset is followed.
        std::os::unix::fs::symlink("0", v.join("1")).unwrap();
        let inside = v.join("1").join(&meta);
        assert_eq!(read_beneath(&ds.root, &inside, 100).unwrap(), b"{}");
        // Swap the bucket for a link to the canary, after the walk.
        std::fs::rename(&bucket, v.join("moved")).unwrap();
        std::os::unix::fs::symlink(canary.path(), &bucket).unwrap();
        let got = read_beneath(&ds.root, &s.metadata_path(), 100);
        assert!(matches!(got, Err(ReadError::LeadsOut)), "{got:?}");
        assert!(ds.read(&s.metadata_path(), 100).is_err());
        // Relative links climbing out, and `..` in the path, are refused the same way.
        std::fs::remove_file(&bucket).unwrap();
        let up = format!("../../{}", canary.path().display());
        std::os::unix::fs::symlink(&up, &bucket).unwrap();
        let got = read_beneath(&ds.root, &s.metadata_path(), 100);
        assert!(matches!(got, Err(ReadError::LeadsOut)), "{got:?}");
        let dotdot = ds.root.join("..").join("x");
        assert!(matches!(
            read_beneath(&ds.root, &dotdot, 100),
            Err(ReadError::LeadsOut)
        ));
        // Given through a link to the root (the command line's path), the root is found.
        let alias_dir = tempfile::tempdir().unwrap();
        let alias = alias_dir.path().join("alias");
        std::os::unix::fs::symlink(&ds.root, &alias).unwrap();
        let via = alias.join("clevrtex_camo").join("moved").join(&meta);
        assert_eq!(read_beneath(&ds.root, &via, 100).unwrap(), b"{}");
    }

    #[test]
    fn recorded_splits_win_and_unrecorded_ones_follow_the_position_rule() {
        use layout::Split::{Test, Train, Val};
        // A dataset grown in two runs of 10 (`--total` 10 each): what each run recorded.
        let mut grown: Vec<Option<layout::Split>> = Vec::new();
        for _run in 0..2 {
            grown.push(Some(Test));
            grown.push(Some(Val));
            grown.extend(std::iter::repeat_n(Some(Train), 8));
        }
        let s = splits("full", &grown);
        assert_eq!((s[1], s[2], s[11]), (Val, Train, Val));
        assert_eq!(split_sizes(&s), "test 2, val 2, train 16");
        // None recorded (the published ClevrTex): the public loader's positions.
        let s = splits("full", &[None; 20]);
        assert_eq!(split_sizes(&s), "test 2, val 2, train 16");
        assert_eq!((s[1], s[2], s[4]), (Test, Val, Train));
        assert_eq!(
            split_sizes(&splits("outd", &[None; 7])),
            "test 7, val 0, train 0"
        );
    }
}
