//! The run manifest's writing side (its types and reading: [`clevrtex_scene::manifest`], re-exported
//! here): the hashes of a run's files, and the atomic write of `MANIFEST-<start>-<end>-<k>of<n>.json`.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use rayon::prelude::*;

pub use clevrtex_scene::manifest::*;

use crate::error::{RenderError, Result};

/// Size and hash of each of `files` (paths relative to `root`), in parallel.
pub fn hash_files(root: &Path, files: &[String]) -> Result<BTreeMap<String, FileEntry>> {
    files
        .par_iter()
        .map(|rel| {
            let path = root.join(rel);
            let bytes = std::fs::read(&path).map_err(|e| {
                RenderError::io(
                    "cannot read",
                    &path,
                    e,
                    "a finished sample's file vanished while the manifest was written; rerun",
                )
            })?;
            Ok((
                rel.clone(),
                FileEntry {
                    size: bytes.len() as u64,
                    xxh3: hash_hex(&bytes),
                },
            ))
        })
        .collect()
}

/// Writing a manifest (a trait: the type lives in the `scene` crate).
pub trait WriteManifest {
    /// Write to `variant_dir/`[`Manifest::name`] through a temporary file and a rename.
    fn write(&self, variant_dir: &Path) -> Result<PathBuf>;
}

impl WriteManifest for Manifest {
    fn write(&self, variant_dir: &Path) -> Result<PathBuf> {
        let path = variant_dir.join(self.name());
        let tmp = variant_dir.join(format!(
            "{}.{}{}",
            self.name(),
            crate::tmp::owner_tag(),
            crate::output::TMP_SUFFIX
        ));
        let text = serde_json::to_string_pretty(self).expect("manifest serialises") + "\n";
        crate::post::write_file(&tmp, text.as_bytes())?;
        std::fs::rename(&tmp, &path).map_err(|e| {
            let _ = std::fs::remove_file(&tmp);
            RenderError::write(&path, e)
        })?;
        Ok(path)
    }
}
