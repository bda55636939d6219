//! Scene files as `clevrtex sample` writes them: each through the atomic writer without a
//! sync of its own ([`write`]: readers see a whole file or none), made durable once at the end
//! of the run and committed by the manifest of the range sampled ([`commit`]:
//! `SCENES-<start>-<end>-<k>of<n>.manifest` in the variant folder, written and synced last).
//! A folder without the manifest of a range may hold files of an interrupted or crashed run
//! (whole, but after a power loss possibly empty or missing): rerunning the same command
//! rewrites every file and commits them. The manifest's name does not end in `.json`, so
//! `clevrtex render DIR` never takes it for a scene file.

use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

use crate::atomic;

/// `format` of a scene-files manifest.
pub const FORMAT: &str = "clevrtex-scenes";
/// Its extension.
pub const SUFFIX: &str = ".manifest";

/// What a run of `clevrtex sample` committed: the range, shard and draw it made and how many
/// files, all of them durable when this is on disk.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ScenesManifest {
    /// [`FORMAT`].
    pub format: String,
    /// 1.
    pub version: u32,
    /// The variant (its config's name).
    pub variant: String,
    /// Run seed.
    pub seed: u64,
    /// The layout stream the layouts were drawn from.
    pub layout_stream: String,
    /// First index of the range.
    pub start: u64,
    /// One past its last index.
    pub end: u64,
    /// The dataset's size (fixes the splits).
    pub total: u64,
    /// `[k, n]`: the run made the indices with `index % n == k`.
    pub shard: [u64; 2],
    /// Scene files written.
    pub files: u64,
    /// The clevrtex version that wrote them.
    pub tool_version: String,
}

impl ScenesManifest {
    /// Its file name: `SCENES-<start>-<end>-<k>of<n>.manifest`.
    pub fn name(&self) -> String {
        format!(
            "SCENES-{}-{}-{}of{}{SUFFIX}",
            self.start, self.end, self.shard[0], self.shard[1]
        )
    }
}

/// Write scene file `path` (its folder exists) with `bytes`, atomically but without a sync:
/// [`commit`] makes it durable.
pub fn write(path: &Path, bytes: &[u8]) -> std::io::Result<()> {
    atomic::write_unsynced(path, bytes)
}

/// Make every file written so far durable (one `syncfs` of the file system holding
/// `variant_dir`), then write `m` into `variant_dir` (synced): the run's commit point.
pub fn commit(variant_dir: &Path, m: &ScenesManifest) -> std::io::Result<PathBuf> {
    atomic::sync_filesystem(variant_dir)?;
    let path = variant_dir.join(m.name());
    let text = serde_json::to_string_pretty(m).map_err(std::io::Error::other)?;
    atomic::write(&path, format!("{text}\n").as_bytes())?;
    Ok(path)
}
