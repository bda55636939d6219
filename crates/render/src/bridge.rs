//! The embedded Blender bridge (`blender_scripts/`) and the private folder it runs from.

use std::path::{Path, PathBuf};

use crate::error::{RenderError, Result};

include!(concat!(env!("OUT_DIR"), "/bridge_files.rs"));

/// Bridge protocol version this crate speaks (`bridge_version` of the `ready` reply).
pub const BRIDGE_VERSION: u64 = 1;

/// Every embedded bridge file, as (path relative to `blender_scripts/`, contents): all of
/// `blender_scripts/` but the development tools of `blender_scripts/dev/`.
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
        // Folders of earlier runs that were killed (so never cleaned up) go first.
        crate::tmp::remove_stale();
        let dir = crate::tmp::private_dir("clevrtex-bridge-")?;
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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_run_time_script_is_embedded_and_no_dev_tool() {
        for name in [
            "worker.py",
            "compat.py",
            "compat_principled.py",
            "builder.py",
            "shapes.py",
            "passes.py",
            "materials.py",
            "material_tool.py",
            "phases.py",
            "shading.py",
        ] {
            assert!(file(name).is_some(), "`{name}` is not embedded");
        }
        let dev: Vec<&str> = files()
            .iter()
            .map(|(n, _)| *n)
            .filter(|n| n.starts_with("dev/"))
            .collect();
        assert!(dev.is_empty(), "development tools embedded: {dev:?}");
    }
}
