//! The run-private copies of user material files: every file a user material makes Blender
//! read (a `.blend`, the images its node group reads, a JSON material's `image` layers, a PBR
//! folder's maps) is read once from inside its material folder (no link out followed, on any
//! component: [`clevrtex_dataset::dataset::read_beneath`]), checked on those bytes
//! ([`clevrtex_materials::texture::bytes_problem`]) and written to a private folder of this
//! process; the bridge is given only the copies. A file swapped or edited after the check
//! therefore never reaches Blender, not even when a worker first uses the material late or
//! restarts, and the material's hash is the hash of what Blender reads (docs/security.md).

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use clevrtex_dataset::dataset::{read_beneath, ReadError};
use clevrtex_materials::texture::{bytes_problem, Expect};
use clevrtex_scene::text::printable;

use crate::error::{RenderError, Result};

/// The private folder of one run's copies, removed when dropped (or, after a `kill -9`, by a
/// later run: `clevrtex_render::tmp`).
pub struct Copies {
    dir: crate::tmp::TempDir,
    /// (material, file in its folder) -> the copy, so a file read twice is copied once.
    done: BTreeMap<(String, PathBuf), PathBuf>,
}

/// One file copied: where the copy is and the file's path inside its material folder (what
/// the manifest records).
pub struct Copied {
    /// The copy, in the private folder: what Blender reads.
    pub copy: PathBuf,
    /// The file's path inside its material folder.
    pub rel: String,
}

impl Copies {
    /// An empty private folder for this run's copies.
    pub fn new() -> Result<Copies> {
        Ok(Copies {
            dir: crate::tmp::scratch_dir()?,
            done: BTreeMap::new(),
        })
    }

    /// The folder of material `material`'s copies: its files keep their places relative to
    /// the material folder in it (so a `.blend`'s `//textures/x.png` points at the place of
    /// the copy of `textures/x.png`).
    pub fn base(&self, material: &str) -> PathBuf {
        self.dir.path().join("materials").join(material)
    }

    /// Read `path`, a file of user material `material` (shown as `shown`, the material's own
    /// file) that must lie inside the canonical folder `root`, check it as `expect` says, and
    /// copy it to this run's private folder.
    pub fn copy(
        &mut self,
        material: &str,
        shown: &str,
        root: &Path,
        path: &Path,
        expect: Expect,
    ) -> Result<Copied> {
        let what = match expect {
            Expect::Blend => "file",
            Expect::Texture | Expect::PbrMap { .. } => "texture",
        };
        let intro = format!(
            "user material `{material}` (`{shown}`): {what} `{}`",
            printable(&path.display().to_string())
        );
        let rel = clevrtex_dataset::dataset::relative_to_root(root, path);
        let bytes = match rel.as_ref().map(|r| read_beneath(root, &root.join(r), expect.max_bytes())) {
            Some(Ok(b)) => b,
            None | Some(Err(ReadError::LeadsOut)) => refuse!(
                "{intro} is outside the material folder `{}`\nhint: copy the file into the material folder and reference it relative to the material (`//textures/...` in a `.blend`, `textures/...` in a JSON material); a link out of the folder is not followed",
                root.display()
            ),
            Some(Err(ReadError::NotRegular)) => refuse!(
                "{intro} is not a regular file (a FIFO, socket or device)\nhint: reference an image file"
            ),
            Some(Err(ReadError::TooLarge { len, cap })) => refuse!(
                "{intro} is {} bytes, more than the {cap} allowed\nhint: use a smaller resolution (3K or 4K)",
                len.map_or_else(|| "over".into(), |l| l.to_string())
            ),
            Some(Err(ReadError::Io(e))) => refuse!(
                "{intro} cannot be read: {e}\nhint: put the file where the material expects it (beside a `.blend`, usually in `textures/`), or remove the material from the folder; Blender would render it pink"
            ),
        };
        if let Some(problem) = bytes_problem(&bytes, expect) {
            refuse!("{intro} {problem}\nhint: {}", expect.hint());
        }
        let rel = rel.expect("read above");
        let key = (material.to_string(), normal(&rel));
        if let Some(copy) = self.done.get(&key) {
            return Ok(Copied {
                copy: copy.clone(),
                rel: key.1.to_string_lossy().into_owned(),
            });
        }
        let copy = self.base(material).join(&key.1);
        self.write(&copy, &bytes)?;
        self.done.insert(key.clone(), copy.clone());
        Ok(Copied {
            copy,
            rel: key.1.to_string_lossy().into_owned(),
        })
    }

    /// Check `path`, a file this run's Blender wrote into the private folder (a packed image
    /// of a `.blend` copy), as `expect` says; it is itself the copy Blender will read.
    pub fn check_own(
        &self,
        material: &str,
        shown: &str,
        what: &str,
        path: &Path,
        expect: Expect,
    ) -> Result<()> {
        let root = self.dir.path().canonicalize().map_err(|e| {
            RenderError::Refused(format!(
                "cannot read this run's private folder `{}`: {e}\nhint: set `TMPDIR` to a writable folder with free space",
                self.dir.path().display()
            ))
        })?;
        let bytes = read_beneath(&root, path, expect.max_bytes()).map_err(|e| {
            RenderError::Refused(format!(
                "user material `{material}` (`{shown}`): {what} {e}"
            ))
        })?;
        if let Some(problem) = bytes_problem(&bytes, expect) {
            refuse!(
                "user material `{material}` (`{shown}`): {what} {problem}\nhint: {}",
                expect.hint()
            );
        }
        Ok(())
    }

    fn write(&self, copy: &Path, bytes: &[u8]) -> Result<()> {
        let parent = copy.parent().expect("under the private folder");
        std::fs::create_dir_all(parent)
            .and_then(|()| std::fs::write(copy, bytes))
            .map_err(|e| {
                RenderError::Refused(format!(
                    "cannot copy a user material's file into `{}`: {e}\nhint: set `TMPDIR` to a writable folder with free space",
                    parent.display()
                ))
            })
    }
}

/// `rel` without `.` components (`..` cannot be left: `read_beneath` refused any that climbs
/// out, and one inside is kept as the copy's place).
fn normal(rel: &Path) -> PathBuf {
    rel.components()
        .filter(|c| !matches!(c, std::path::Component::CurDir))
        .collect()
}
