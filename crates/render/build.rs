//! Embeds the bridge, every file of `blender_scripts/` except the development tools in
//! `blender_scripts/dev/`, into the library, so an installed `clevrtex` binary never hunts
//! for it on disk. This is the one set of scripts every Blender run uses (`generate`,
//! `render`, `bench`, `materials`, `doctor`). Generates `$OUT_DIR/bridge_files.rs` holding
//! `BRIDGE_FILES: &[(relative path, contents)]`.

use std::fmt::Write as _;
use std::path::{Path, PathBuf};

fn main() {
    let manifest = PathBuf::from(std::env::var_os("CARGO_MANIFEST_DIR").expect("cargo sets it"));
    let scripts = manifest.join("../../blender_scripts");
    println!("cargo:rerun-if-changed={}", scripts.display());
    let mut files = Vec::new();
    collect(&scripts, &scripts, &mut files);
    files.sort();
    let mut out =
        String::from("/// Every bridge file: (path relative to `blender_scripts/`, contents).\n");
    out.push_str("pub(crate) const BRIDGE_FILES: &[(&str, &str)] = &[\n");
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
    let dest =
        PathBuf::from(std::env::var_os("OUT_DIR").expect("cargo sets it")).join("bridge_files.rs");
    std::fs::write(dest, out).expect("write bridge_files.rs");
}

/// Development tools (`blender_scripts/dev/`): not needed at run time, so not embedded.
const DEV_DIR: &str = "dev";

/// Python files (and JSON data files) under `dir`, recursively; caches and the development
/// tools are skipped.
fn collect(root: &Path, dir: &Path, files: &mut Vec<(String, PathBuf)>) {
    let Ok(entries) = std::fs::read_dir(dir) else {
        return;
    };
    for entry in entries.flatten() {
        let path = entry.path();
        let name = entry.file_name().to_string_lossy().into_owned();
        if name.starts_with('.') || name == "__pycache__" || (dir == root && name == DEV_DIR) {
            continue;
        }
        if path.is_dir() {
            // Subfolders get their own rerun trigger so new files are picked up.
            println!("cargo:rerun-if-changed={}", path.display());
            collect(root, &path, files);
        } else if name.ends_with(".py") || name.ends_with(".json") {
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
