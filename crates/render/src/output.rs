//! Crash-safe writing of a sample's files into the published layout (whose names and
//! folders live in [`clevrtex_dataset::layout`]).
//!
//! Each file is written under a temporary name and renamed once every file of the sample
//! is ready, metadata last; a sample is complete only when all its files exist.

use std::io::Write;
use std::path::{Path, PathBuf};

use clevrtex_dataset::atomic::AtomicFile;
use clevrtex_dataset::layout::{expected_files, legacy_exr_files};
use clevrtex_scene::Pass;

use crate::error::{RenderError, Result};

/// Suffix of temporary files (the layout's, [`clevrtex_dataset::layout::TMP_SUFFIX`]).
pub use clevrtex_dataset::layout::TMP_SUFFIX;

/// Whether every file of the sample exists in `dir`.
pub fn is_complete(dir: &Path, stem: &str, passes: &[Pass], keep_exr: bool) -> bool {
    expected_files(stem, passes, keep_exr)
        .iter()
        .all(|f| dir.join(f).is_file())
}

/// Remove the files of `stem` that a sample written with `passes` does not have: left by an
/// earlier run with other passes (or `--keep-exr`, also under the names of earlier versions),
/// they would sit beside the new image without matching it.
pub fn remove_other_outputs(dir: &Path, stem: &str, passes: &[Pass], keep_exr: bool) {
    let keep = expected_files(stem, passes, keep_exr);
    let mut all = expected_files(stem, &Pass::ALL, true);
    all.extend(legacy_exr_files(stem));
    for f in all.iter().filter(|f| !keep.contains(f)) {
        let _ = std::fs::remove_file(dir.join(f));
    }
}

/// Remove temporary files a killed run left in `dir` (the one sweep:
/// [`clevrtex_dataset::atomic::remove_stale_temps`]).
pub use clevrtex_dataset::atomic::remove_stale_temps;

/// Files of one sample being written: each an [`AtomicFile`] (a unique temporary) until
/// [`Staged::commit`]. Dropping without committing removes the temporaries, so no partial
/// sample is left.
#[derive(Debug)]
pub struct Staged {
    dir: PathBuf,
    files: Vec<AtomicFile>,
}

impl Staged {
    /// Start staging files into `dir`, a sample folder of the layout under `out` (created if
    /// missing; a link out of `out` or anything but a folder in its place is refused:
    /// [`clevrtex_dataset::layout::make_dir`]).
    pub fn new(out: &Path, dir: &Path) -> Result<Staged> {
        clevrtex_dataset::layout::make_dir(out, dir).map_err(RenderError::Refused)?;
        Ok(Staged {
            dir: dir.to_path_buf(),
            files: Vec::new(),
        })
    }

    /// Write `bytes` as the future `name` (synced to disk, so a full disk is reported here).
    pub fn write(&mut self, name: &str, bytes: &[u8]) -> Result<()> {
        let path = self.dir.join(name);
        let mut f = AtomicFile::create(&path).map_err(|e| RenderError::write(&path, e))?;
        f.write_all(bytes)
            .and_then(|()| f.sync())
            .map_err(|e| RenderError::write(f.tmp_path(), e))?;
        self.files.push(f);
        Ok(())
    }

    /// Copy the file `from` as the future `name`.
    pub fn copy(&mut self, name: &str, from: &Path) -> Result<()> {
        let bytes = std::fs::read(from).map_err(|e| {
            RenderError::io(
                "cannot read render output",
                from,
                e,
                "the Blender worker's temporary folder vanished; rerun",
            )
        })?;
        self.write(name, &bytes)
    }

    /// Rename every temporary to its final name, in the order written (write the metadata
    /// last: its presence then means everything else is there). On error the temporaries
    /// not yet renamed are removed.
    pub fn commit(mut self) -> Result<()> {
        for f in std::mem::take(&mut self.files) {
            let path = f.path().to_path_buf();
            f.commit().map_err(|e| RenderError::write(&path, e))?;
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use clevrtex_dataset::layout::pass_file;

    #[test]
    fn layout_matches_the_reference() {
        let stem = "CLEVRTEX_camo_012345";
        assert_eq!(pass_file(stem, Pass::Mask), "CLEVRTEX_camo_012345_flat.png");
        assert_eq!(
            expected_files(stem, &[Pass::Rgb, Pass::Depth], false),
            vec![
                "CLEVRTEX_camo_012345.png",
                "CLEVRTEX_camo_012345_depth_0001.png",
                "CLEVRTEX_camo_012345.json"
            ]
        );
    }

    #[test]
    fn other_outputs_of_the_stem_are_removed() {
        let dir = tempfile::tempdir().unwrap();
        let stem = "CLEVRTEX_camo_000000";
        let mut all = expected_files(stem, &Pass::ALL, true);
        // The shadow pass's EXRs as `--keep-exr` named them before the one-render pass.
        all.extend(legacy_exr_files(stem));
        for f in all
            .iter()
            .chain(["CLEVRTEX_camo_000001_depth_0001.png".to_string()].iter())
        {
            std::fs::write(dir.path().join(f), b"x").unwrap();
        }
        remove_other_outputs(dir.path(), stem, &[Pass::Rgb, Pass::Mask], false);
        let mut left: Vec<String> = std::fs::read_dir(dir.path())
            .unwrap()
            .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
            .collect();
        left.sort();
        assert_eq!(
            left,
            [
                "CLEVRTEX_camo_000000.json",
                "CLEVRTEX_camo_000000.png",
                "CLEVRTEX_camo_000000_flat.png",
                "CLEVRTEX_camo_000001_depth_0001.png",
            ]
        );
    }

    #[test]
    fn uncommitted_files_vanish() {
        let dir = tempfile::tempdir().unwrap();
        {
            let mut s = Staged::new(dir.path(), dir.path()).unwrap();
            s.write("a.png", b"x").unwrap();
        }
        assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 0);
        let mut s = Staged::new(dir.path(), dir.path()).unwrap();
        s.write("a.png", b"x").unwrap();
        s.commit().unwrap();
        assert!(dir.path().join("a.png").is_file());
        assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 1);
    }
}
