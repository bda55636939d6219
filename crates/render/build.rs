//! Embeds the bridge, every file of `blender_scripts/` except the development tools in
//! `blender_scripts/dev/`, into the library, so an installed `clevrtex` binary never hunts
//! for it on disk. This is the one set of scripts every Blender run uses (`generate`,
//! `render`, `bench`, `materials`, `doctor`). Generates `$OUT_DIR/bridge_files.rs` holding
//! `BRIDGE_FILES: &[(relative path, contents)]`.

#[path = "../build/embed.rs"]
mod embed;

/// Development tools (`blender_scripts/dev/`): not needed at run time, so not embedded.
const DEV_DIR: &str = "dev";

fn main() {
    // Python files (and JSON data files); caches and the development tools are skipped.
    embed::embed(&embed::Embed {
        dir: "../../blender_scripts",
        endings: &[".py", ".json"],
        skip: &[DEV_DIR],
        out: "bridge_files.rs",
        item: "/// Every bridge file: (path relative to `blender_scripts/`, contents).\npub(crate) const BRIDGE_FILES: &[(&str, &str)]",
    });
}
