//! The embedded Blender bridge (`blender_scripts/`) and the private folder it runs from.

use std::path::{Path, PathBuf};

use crate::error::{RenderError, Result};

include!(concat!(env!("OUT_DIR"), "/bridge_files.rs"));

/// Bridge protocol version this crate speaks (`bridge_version` of the `ready` reply).
pub const BRIDGE_VERSION: u64 = 1;

/// Every embedded bridge file, as (path relative to `blender_scripts/`, contents).
pub fn files() -> &'static [(&'static str, &'static str)] {
    BRIDGE_FILES
}

/// The contents of one embedded bridge file, e.g. `worker.py`.
pub fn file(name: &str) -> Option<&'static str> {
    BRIDGE_FILES
        .iter()
        .find(|(n, _)| *n == name)
        .map(|(_, text)| *text)
}

/// A private temporary folder holding the bridge scripts and the resolved material
/// catalogue (`materials.json`); removed when dropped. Shared by every worker of a run.
#[derive(Debug)]
pub struct BridgeDir {
    dir: tempfile::TempDir,
}

impl BridgeDir {
    /// Write the embedded scripts and `materials_json` (the resolved catalogue, see
    /// `docs/bridge-protocol.md`) into a fresh temporary folder.
    pub fn create(materials_json: &str) -> Result<BridgeDir> {
        let dir = tempfile::Builder::new()
            .prefix("clevrtex-bridge-")
            .tempdir()
            .map_err(|e| {
                RenderError::io(
                    "cannot create a temporary folder in",
                    std::env::temp_dir(),
                    e,
                    "set `TMPDIR` to a writable folder",
                )
            })?;
        for (rel, text) in BRIDGE_FILES {
            let path = dir.path().join(rel);
            if let Some(parent) = path.parent() {
                std::fs::create_dir_all(parent).map_err(|e| RenderError::write(parent, e))?;
            }
            std::fs::write(&path, text).map_err(|e| RenderError::write(&path, e))?;
        }
        let materials = dir.path().join("materials.json");
        std::fs::write(&materials, materials_json)
            .map_err(|e| RenderError::write(&materials, e))?;
        Ok(BridgeDir { dir })
    }

    /// The folder.
    pub fn path(&self) -> &Path {
        self.dir.path()
    }

    /// The worker entry script.
    pub fn worker_script(&self) -> PathBuf {
        self.dir.path().join("worker.py")
    }

    /// The resolved material catalogue.
    pub fn materials_json(&self) -> PathBuf {
        self.dir.path().join("materials.json")
    }
}

/// The pass table keys of the bridge (`PASSES = {...}` in `blender_scripts/passes.py` or
/// `worker.py`), read from the embedded source, so a test can check they match
/// [`clevrtex_scene::Pass::ALL`]. `None` when no such table is found.
pub fn bridge_pass_names() -> Option<Vec<String>> {
    for (_, text) in BRIDGE_FILES {
        if let Some(names) = parse_pass_table(text) {
            return Some(names);
        }
    }
    None
}

/// Keys of a top-level `PASSES = {` dict literal: each line inside that starts with a quoted
/// key followed by `:`.
fn parse_pass_table(text: &str) -> Option<Vec<String>> {
    let mut lines = text.lines();
    lines.find(|l| {
        let l = l.trim_start();
        l.starts_with("PASSES") && l.contains('{') && !l.trim_end().ends_with('}')
    })?;
    let mut names = Vec::new();
    for line in lines {
        let t = line.trim();
        if line.starts_with('}') || t == "}" {
            break;
        }
        // Only keys at the first indentation level: nested dicts are indented further.
        let indent = line.len() - line.trim_start().len();
        if indent != 4 {
            continue;
        }
        let quote = match t.chars().next() {
            Some(q @ ('"' | '\'')) => q,
            _ => continue,
        };
        let rest = &t[1..];
        if let Some(end) = rest.find(quote) {
            if rest[end + 1..].trim_start().starts_with(':') {
                names.push(rest[..end].to_string());
            }
        }
    }
    Some(names)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parses_a_pass_table() {
        let src = "X = 1\nPASSES = {\n    \"rgb\": {\"exr\": None},\n    'mask': {\n        \"inner\": 1,\n    },\n}\n";
        assert_eq!(parse_pass_table(src).unwrap(), vec!["rgb", "mask"]);
        assert!(parse_pass_table("PASSES = {}\n").is_none());
    }
}
