//! Scene files read back for `clevrtex render`: found in the paths given ([`collect`]: files,
//! and folders searched as `clevrtex sample --out` lays them out) and each read capped,
//! checked and validated ([`read`]). A scene file is not trusted.

use std::path::{Path, PathBuf};

use clevrtex_scene::SceneFile;

/// The scene files of `paths` (files as given, folders searched recursively for `*.json`,
/// sorted per folder); `warn` gets a line per file skipped (a link out of its folder) and one
/// per variant folder holding files no scene-files manifest commits.
pub fn collect(paths: &[PathBuf], warn: &mut dyn FnMut(String)) -> Result<Vec<PathBuf>, String> {
    let mut files = Vec::new();
    for p in paths {
        if p.is_dir() {
            let mut found = Vec::new();
            let root = crate::dataset::root(p)
                .map_err(|e| format!("cannot read folder `{}`: {e}", p.display()))?;
            find(&root, p, &mut found, warn)?;
            found.sort();
            files.extend(found);
        } else if p.is_file() {
            files.push(p.clone());
        } else if p.exists() {
            return Err(format!(
                "scene path `{}` is neither a file nor a folder (a FIFO or device is not read)\nhint: pass scene files or folders written by `clevrtex sample`",
                p.display()
            ));
        } else {
            return Err(format!(
                "scene path `{}` does not exist\nhint: pass scene files or folders written by `clevrtex sample`",
                p.display()
            ));
        }
    }
    if files.is_empty() {
        let searched: Vec<String> = paths.iter().map(|p| format!("`{}`", p.display())).collect();
        return Err(format!(
            "no `*.json` scene files found in {}\nhint: make some with `clevrtex sample --out DIR` and pass that `DIR`",
            searched.join(", ")
        ));
    }
    // Files of a killed or running `clevrtex sample` (or put there by hand) are whole but not
    // known to be durable nor to be one run's: rendered, but said.
    for (dir, n) in crate::scene_files::uncommitted(&files) {
        warn(format!(
            "warning: {n} scene file(s) under `{}` are committed by no `SCENES-*.manifest`: a `clevrtex sample` run was killed (or is still running) there, or the files were put there otherwise\nhint: rerun the `clevrtex sample` command that wrote them (it rewrites and commits them), then `clevrtex render` again",
            clevrtex_scene::text::printable(&dir.display().to_string())
        ));
    }
    Ok(files)
}

/// Collect the `*.json` files under `dir` (in the folder given, canonical `root`),
/// recursively (not into linked folders): `clevrtex sample --out DIR` writes them to
/// `DIR/clevrtex_<variant>/<index / 1000>/`, and `clevrtex render DIR` must find them. A file
/// link leading out of the folder given is not followed (the folder is untrusted), and said.
fn find(
    root: &Path,
    dir: &Path,
    found: &mut Vec<PathBuf>,
    warn: &mut dyn FnMut(String),
) -> Result<(), String> {
    let entries = std::fs::read_dir(dir).map_err(|e| {
        format!(
            "cannot read folder `{}`: {e}\nhint: pass a readable folder of scene files",
            dir.display()
        )
    })?;
    for entry in entries.flatten() {
        let path = entry.path();
        // Links to folders are not followed: a link back up (`loop -> ..`) would walk the same
        // scenes again without end.
        if entry.file_type().is_ok_and(|t| t.is_dir()) {
            find(root, &path, found, warn)?;
        } else if path.extension().is_some_and(|e| e == "json") {
            match crate::dataset::classify(root, &path) {
                crate::dataset::Kind::File => found.push(path),
                crate::dataset::Kind::Skipped(why) => warn(format!(
                    "warning: scene file `{}` {}",
                    clevrtex_scene::text::printable(&path.display().to_string()),
                    why
                )),
                crate::dataset::Kind::Dir => {}
            }
        }
    }
    Ok(())
}

/// The largest scene file read: `clevrtex sample` writes a few KB (at most 255 objects); a
/// scene file is not trusted, and its size must not size our memory.
const MAX_SCENE_BYTES: u64 = 4 << 20;

/// One scene file read (at most [`MAX_SCENE_BYTES`]), its format and version checked and
/// validated ([`SceneFile::validate`]).
pub fn read(path: &Path) -> Result<SceneFile, String> {
    let cannot = |e: std::io::Error| {
        format!(
            "cannot read scene file `{}`: {e}\nhint: pass scene files written by `clevrtex sample`",
            path.display()
        )
    };
    let mut file = std::fs::File::open(path).map_err(cannot)?;
    let mut bytes = Vec::new();
    std::io::Read::read_to_end(
        &mut std::io::Read::take(&mut file, MAX_SCENE_BYTES + 1),
        &mut bytes,
    )
    .map_err(cannot)?;
    if bytes.len() as u64 > MAX_SCENE_BYTES {
        return Err(format!(
            "scene file `{}` is larger than {} MiB; `clevrtex sample` writes a few KB\nhint: pass scene files written by `clevrtex sample`",
            path.display(),
            MAX_SCENE_BYTES >> 20
        ));
    }
    let text = String::from_utf8(bytes).map_err(|e| {
        format!(
            "bad scene file `{}`: not UTF-8 text ({e})\nhint: regenerate it with `clevrtex sample`",
            path.display()
        )
    })?;
    let scene: SceneFile = serde_json::from_str(&text).map_err(|e| {
        format!(
            "bad scene file `{}`: {e}\nhint: regenerate it with `clevrtex sample`",
            path.display()
        )
    })?;
    if scene.format != clevrtex_scene::scene_file::SCENE_FORMAT
        || scene.version != clevrtex_scene::scene_file::SCENE_VERSION
    {
        return Err(format!(
            "`{}` is not a version {} clevrtex scene file (format `{}`, version {})\nhint: regenerate it with this version's `clevrtex sample`",
            path.display(),
            clevrtex_scene::scene_file::SCENE_VERSION,
            scene.format,
            scene.version
        ));
    }
    if let Err(problem) = scene.validate() {
        return Err(format!(
            "bad scene file `{}`: {problem}\nhint: fix that key, or regenerate the file with `clevrtex sample`",
            path.display()
        ));
    }
    Ok(scene)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn scene_files_are_found_capped_and_checked() {
        let dir = tempfile::tempdir().unwrap();
        let mut warnings = Vec::new();
        let e = collect(&[dir.path().to_path_buf()], &mut |w| warnings.push(w)).unwrap_err();
        assert!(e.contains("no `*.json` scene files found"), "{e}");
        let e = collect(&[dir.path().join("nope")], &mut |w| warnings.push(w)).unwrap_err();
        assert!(e.contains("does not exist"), "{e}");
        let sub = dir.path().join("clevrtex_x/0");
        std::fs::create_dir_all(&sub).unwrap();
        let (a, b) = (sub.join("b.json"), sub.join("a.json"));
        std::fs::write(&a, b"{}").unwrap();
        std::fs::write(&b, vec![b' '; (MAX_SCENE_BYTES + 1) as usize]).unwrap();
        let found = collect(&[dir.path().to_path_buf()], &mut |w| warnings.push(w)).unwrap();
        assert_eq!(found, vec![b.clone(), a.clone()]);
        assert!(warnings.is_empty());
        assert!(read(&b).unwrap_err().contains("larger than 4 MiB"));
        assert!(read(&a).unwrap_err().starts_with("bad scene file"));
    }
}
