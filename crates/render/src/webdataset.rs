//! WebDataset tar shards, as `clevrtex export` writes them: the shard names
//! (`<variant>-<split>-<6 digits>.tar`, [`shard_name`], [`is_shard_name`]) and the writer of
//! one shard ([`ShardWriter`]: reproducible headers, a temporary name until complete).

use std::path::{Path, PathBuf};

use clevrtex_scene::layout::Split;
use serde_json::{json, Value};

use crate::dataset;

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

/// A tar shard being written under a temporary name (removed if it is never finished).
pub struct ShardWriter {
    tmp: PathBuf,
    path: PathBuf,
    /// `None` once finished.
    builder: Option<tar::Builder<std::io::BufWriter<std::fs::File>>>,
    bytes: u64,
    samples: u64,
    first: u64,
    last: u64,
}

impl ShardWriter {
    /// Start the shard `path` (written as `<path>.clevrtex-tmp` until [`ShardWriter::finish`]).
    pub fn create(path: PathBuf) -> Result<ShardWriter, ShardError> {
        let tmp = path.with_extension("tar.clevrtex-tmp");
        let f = std::fs::File::create(&tmp).map_err(io("cannot create", &tmp))?;
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

    /// Add sample `index` with key `stem`: each `(extension, path)` of `files`, read from the
    /// dataset under its canonical `root` ([`dataset::read`]), becomes `<stem>.<extension>`.
    /// Headers carry no time, owner or mode of the machine.
    pub fn add(
        &mut self,
        root: &Path,
        index: u64,
        stem: &str,
        files: &[(String, PathBuf)],
    ) -> Result<(), ShardError> {
        for (ext, path) in files {
            let data = dataset::read(root, path, dataset::MAX_FILE_BYTES).map_err(|why| {
                ShardError::Read(format!(
                    "`{}` {why}\nhint: check the dataset with `clevrtex verify`",
                    path.display()
                ))
            })?;
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
        f.sync_all().map_err(io("cannot write", &self.tmp))?;
        std::fs::rename(&self.tmp, &self.path).map_err(io("cannot write", &self.path))?;
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

impl Drop for ShardWriter {
    fn drop(&mut self) {
        // Unfinished (an error): leave no partial shard.
        let _ = std::fs::remove_file(&self.tmp);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn shard_names_are_recognised_and_nothing_else() {
        assert!(is_shard_name(&shard_name("full", "train", 3)));
        assert_eq!(shard_name("camo", "val", 12), "camo-val-000012.tar");
        for name in [
            "full-train-00003.tar",
            "full-nope-000003.tar",
            "-train-000003.tar",
            "full-train-000003.tar.clevrtex-tmp",
            "index.json",
        ] {
            assert!(!is_shard_name(name), "{name}");
        }
    }

    #[test]
    fn an_unfinished_shard_leaves_nothing_and_a_finished_one_is_reproducible() {
        let dir = tempfile::tempdir().unwrap();
        let data = dir.path().join("data");
        std::fs::create_dir(&data).unwrap();
        std::fs::write(data.join("a.png"), b"not really a png").unwrap();
        let root = dataset::root(&data).unwrap();
        let files = vec![("png".to_string(), data.join("a.png"))];
        let out = dir.path().join("full-train-000000.tar");
        {
            let mut w = ShardWriter::create(out.clone()).unwrap();
            w.add(&root, 7, "CLEVRTEX_full_000007", &files).unwrap();
            assert_eq!((w.samples(), w.bytes()), (1, 1024));
        }
        assert!(
            std::fs::read_dir(dir.path()).unwrap().count() == 1,
            "a temporary shard is left"
        );
        let mut bytes = Vec::new();
        for _ in 0..2 {
            let mut w = ShardWriter::create(out.clone()).unwrap();
            w.add(&root, 7, "CLEVRTEX_full_000007", &files).unwrap();
            let entry = w.finish().unwrap();
            assert_eq!(entry["first_index"], 7);
            assert_eq!(entry["samples"], 1);
            bytes.push(std::fs::read(&out).unwrap());
        }
        assert_eq!(bytes[0], bytes[1]);
        let err = ShardWriter::create(out.clone())
            .unwrap()
            .add(&root, 8, "x", &[("png".into(), data.join("missing.png"))])
            .unwrap_err();
        assert!(err.to_string().contains("missing.png"), "{err}");
        assert!(err.to_string().contains("hint:"), "{err}");
    }
}
