//! One shard of `export`: a sample's entries ([`sample_entries`]), the shard names
//! ([`shard_name`], [`is_shard_name`]) and the writer of one shard ([`ShardWriter`]:
//! reproducible headers, a temporary name until complete).

use std::path::{Path, PathBuf};

use crate::atomic::AtomicFile;
use crate::layout::Split;
use serde_json::{json, Value};

use crate::dataset;

use super::npy::decoded_npy;

pub use crate::export::{PassCheck, SampleFile};

/// What can go wrong while writing a shard. Shown as the command's error: the message, then
/// (as the error's source) the OS error.
#[derive(Debug, thiserror::Error)]
pub enum ShardError {
    /// A file of the shard could not be created or written.
    #[error("{what}")]
    Io {
        /// What failed, e.g. "cannot write `OUT/full-train-000000.tar.clevrtex-tmp`".
        what: String,
        /// The OS error.
        #[source]
        cause: std::io::Error,
    },
    /// The finished shard could not be looked at.
    #[error(transparent)]
    Stat(std::io::Error),
    /// A file of the dataset could not be read (the message says which and what to do).
    #[error("{0}")]
    Read(String),
    /// A pass fails the checks of every reader ([`dataset::check_pass_png`]): the sample is
    /// left out of the export (the message names the file and what is wrong).
    #[error("{0}")]
    Refused(String),
}

fn io(what: &str, path: &Path) -> impl FnOnce(std::io::Error) -> ShardError {
    let what = format!("{what} `{}`", path.display());
    move |cause| ShardError::Io { what, cause }
}

/// The name of shard `n` of `split` of `variant`.
pub fn shard_name(variant: &str, split: &str, n: u64) -> String {
    format!("{variant}-{split}-{n:06}.tar")
}

/// Whether `name` is one of export's shard names, `<variant>-<split>-<6 digits>.tar`.
pub fn is_shard_name(name: &str) -> bool {
    let Some(rest) = name.strip_suffix(".tar") else {
        return false;
    };
    let Some((head, digits)) = rest.rsplit_once('-') else {
        return false;
    };
    let Some((variant, split)) = head.rsplit_once('-') else {
        return false;
    };
    !variant.is_empty()
        && Split::parse(split).is_some()
        && digits.len() == 6
        && digits.bytes().all(|b| b.is_ascii_digit())
}

/// The bytes a tar holds for `entries`: a 512-byte header and the data padded to 512 bytes
/// each.
pub fn tar_bytes(entries: &[(String, Vec<u8>)]) -> u64 {
    entries
        .iter()
        .map(|(_, d)| 512 + (d.len() as u64).div_ceil(512) * 512)
        .sum()
}

/// The entries of one sample in a shard: each file of `files` read from the dataset under its
/// canonical `root` ([`dataset::read`]: no link out of it, only regular files, capped), each
/// pass checked as every reader checks it ([`dataset::check_pass_png`] against `check`:
/// [`ShardError::Refused`] when it fails), one marked for it decoded into its `.npy` array
/// ([`decoded_npy`]).
pub fn sample_entries(
    root: &Path,
    files: &[SampleFile],
    check: &PassCheck,
) -> Result<Vec<(String, Vec<u8>)>, ShardError> {
    let unread = |path: &Path, why: String| {
        ShardError::Read(format!(
            "`{}` {why}\nhint: check the dataset with `clevrtex verify`",
            path.display()
        ))
    };
    // Without a size in the metadata, the first pass's size is every pass's.
    let mut check = *check;
    let mut out = Vec::with_capacity(files.len());
    for f in files {
        let bytes = dataset::read(root, &f.path, dataset::MAX_FILE_BYTES)
            .map_err(|w| unread(&f.path, w))?;
        let data = match f.pass {
            None => bytes,
            Some(pass) => {
                let name = f.path.display().to_string();
                let png = check
                    .check(&name, &bytes, pass)
                    .map_err(ShardError::Refused)?;
                if f.npy {
                    decoded_npy(pass, &png).map_err(|w| unread(&f.path, w))?
                } else {
                    bytes
                }
            }
        };
        out.push((f.key.clone(), data));
    }
    Ok(out)
}

/// A tar shard being written under a unique temporary name (an [`AtomicFile`]: removed if it
/// is never finished).
pub struct ShardWriter {
    tmp: PathBuf,
    path: PathBuf,
    /// `None` once finished.
    builder: Option<tar::Builder<std::io::BufWriter<AtomicFile>>>,
    bytes: u64,
    samples: u64,
    first: u64,
    last: u64,
}

impl ShardWriter {
    /// Start the shard `path` (written under a temporary name of
    /// [`crate::atomic`] until [`ShardWriter::finish`]).
    pub fn create(path: PathBuf) -> Result<ShardWriter, ShardError> {
        let f = AtomicFile::create(&path).map_err(io("cannot create a temporary for", &path))?;
        let tmp = f.tmp_path().to_path_buf();
        Ok(ShardWriter {
            tmp,
            path,
            builder: Some(tar::Builder::new(std::io::BufWriter::new(f))),
            bytes: 0,
            samples: 0,
            first: 0,
            last: 0,
        })
    }

    /// Bytes written so far (tar headers and padding included).
    pub fn bytes(&self) -> u64 {
        self.bytes
    }

    /// Samples written so far.
    pub fn samples(&self) -> u64 {
        self.samples
    }

    /// Add sample `index` with key `stem`: each `(extension, bytes)` of `entries`
    /// ([`sample_entries`]) becomes `<stem>.<extension>`. Headers carry no time, owner or mode
    /// of the machine.
    pub fn add(
        &mut self,
        index: u64,
        stem: &str,
        entries: &[(String, Vec<u8>)],
    ) -> Result<(), ShardError> {
        for (ext, data) in entries {
            let mut h = tar::Header::new_ustar();
            h.set_size(data.len() as u64);
            h.set_mode(0o644);
            h.set_mtime(0);
            h.set_uid(0);
            h.set_gid(0);
            h.set_entry_type(tar::EntryType::Regular);
            let name = format!("{stem}.{ext}");
            self.builder
                .as_mut()
                .expect("not finished")
                .append_data(&mut h, &name, data.as_slice())
                .map_err(io("cannot write", &self.tmp))?;
            self.bytes += 512 + (data.len() as u64).div_ceil(512) * 512;
        }
        if self.samples == 0 {
            self.first = index;
        }
        self.last = index;
        self.samples += 1;
        Ok(())
    }

    /// Finish the tar, flush it to disk and rename it to its final name; its entry of
    /// `index.json` (file, samples, bytes, first and last index).
    pub fn finish(mut self) -> Result<Value, ShardError> {
        let w = self
            .builder
            .take()
            .expect("finished once")
            .into_inner()
            .map_err(io("cannot write", &self.tmp))?;
        let f = w
            .into_inner()
            .map_err(|e| e.into_error())
            .map_err(io("cannot write", &self.tmp))?;
        f.commit().map_err(io("cannot write", &self.path))?;
        let size = std::fs::metadata(&self.path)
            .map_err(ShardError::Stat)?
            .len();
        Ok(json!({
            "file": self.path.file_name().unwrap().to_string_lossy(),
            "samples": self.samples,
            "bytes": size,
            "first_index": self.first,
            "last_index": self.last,
        }))
    }
}
