//! The one job of the workspace's build scripts: embed every file of a folder into the
//! library as a table of (relative path, contents), so an installed binary never hunts for
//! them on disk. `crates/materials/build.rs` (the catalogue, `materials/`) and
//! `crates/render/build.rs` (the Blender bridge, `blender_scripts/`) include this file with
//! `#[path]`.

use std::fmt::Write as _;
use std::path::{Path, PathBuf};

/// What to embed and where the table goes.
pub struct Embed<'a> {
    /// The folder, relative to the crate's manifest directory.
    pub dir: &'a str,
    /// File names ending in one of these are embedded.
    pub endings: &'a [&'a str],
    /// Top-level subfolders left out (besides dot files and `__pycache__` everywhere).
    pub skip: &'a [&'a str],
    /// File name under `$OUT_DIR` that the table is written to.
    pub out: &'a str,
    /// The table's doc comment and declaration, e.g.
    /// `/// ...\npub static EMBEDDED: &[(&str, &str)]`.
    pub item: &'a str,
}

/// Writes the table: every matching file under `dir`, sorted by relative path, as
/// `(relative path, include_str!(absolute path))`; cargo reruns the script when the folder,
/// a subfolder or a file changes.
pub fn embed(e: &Embed<'_>) {
    let manifest = PathBuf::from(std::env::var_os("CARGO_MANIFEST_DIR").expect("cargo sets it"));
    let root = manifest.join(e.dir);
    println!("cargo:rerun-if-changed={}", root.display());
    let mut files = Vec::new();
    collect(e, &root, &root, &mut files);
    files.sort();
    let mut out = format!("{} = &[\n", e.item);
    for (rel, abs) in &files {
        println!("cargo:rerun-if-changed={}", abs.display());
        writeln!(
            out,
            "    ({rel:?}, include_str!({:?})),",
            abs.display().to_string()
        )
        .unwrap();
    }
    out.push_str("];\n");
    let dest = PathBuf::from(std::env::var_os("OUT_DIR").expect("cargo sets it")).join(e.out);
    std::fs::write(&dest, out).unwrap_or_else(|err| panic!("write {}: {err}", dest.display()));
}

fn collect(e: &Embed<'_>, root: &Path, dir: &Path, files: &mut Vec<(String, PathBuf)>) {
    let Ok(entries) = std::fs::read_dir(dir) else {
        return;
    };
    for entry in entries.flatten() {
        let path = entry.path();
        let name = entry.file_name().to_string_lossy().into_owned();
        if name.starts_with('.')
            || name == "__pycache__"
            || (dir == root && e.skip.contains(&name.as_str()))
        {
            continue;
        }
        if path.is_dir() {
            // Subfolders get their own rerun trigger so new files are picked up.
            println!("cargo:rerun-if-changed={}", path.display());
            collect(e, root, &path, files);
        } else if e.endings.iter().any(|end| name.ends_with(end)) {
            let rel = path
                .strip_prefix(root)
                .expect("under root")
                .to_string_lossy()
                .replace('\\', "/");
            let abs = path.canonicalize().unwrap_or(path);
            files.push((rel, abs));
        }
    }
}
