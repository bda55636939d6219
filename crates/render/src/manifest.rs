//! The run manifest: what one `clevrtex generate` run (or one shard of it) made, with the size
//! and xxh3 hash of every file, so `clevrtex verify` can check the bytes later (after a copy,
//! on another machine, for the union of shards).
//!
//! `OUT/clevrtex_<variant>/MANIFEST-<start>-<end>-<k>of<n>.json`: one per range and shard
//! (`0of1` unsharded), so runs of other ranges into one folder (a dataset grown with `--start`)
//! and shards never overwrite each other's; `verify` takes their union. Written atomically
//! twice: before the first image as the run's plan (`finished: false`, no files), and at the
//! end of a run that was not interrupted with every file (`finished: true`). Paths are relative
//! to the variant folder, e.g. `0/CLEVRTEX_full_000000.png`.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use crate::error::{RenderError, Result};

/// Value of [`Manifest::format`].
pub const MANIFEST_FORMAT: &str = "clevrtex-manifest";
/// Current value of [`Manifest::version`].
pub const MANIFEST_VERSION: u32 = 1;
/// The most indices one manifest's range (`end - start`), or the union of a dataset's runs,
/// may hold: 100 million, a hundred times the largest dataset anyone renders. A file with
/// more is refused before anything is sized by it.
pub const MAX_RUN_INDICES: u64 = 100_000_000;

/// One file of the manifest.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct FileEntry {
    /// Size in bytes.
    pub size: u64,
    /// xxh3-64 of the bytes, 16 hex digits.
    pub xxh3: String,
}

/// What one run (or shard) made.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Manifest {
    /// Always [`MANIFEST_FORMAT`].
    pub format: String,
    /// Always [`MANIFEST_VERSION`] for files this version writes.
    pub version: u32,
    /// Variant name.
    pub variant: String,
    /// Run seed.
    pub seed: u64,
    /// xxh3 of the resolved variant config (render settings and passes included), hex.
    pub config_hash: String,
    /// First index of the run.
    pub start: u64,
    /// One past the last index of the run (before sharding).
    pub end: u64,
    /// Size of the whole dataset (fixes the splits).
    pub total: u64,
    /// This shard `[k, n]`: the run made the indices of `start..end` with `index % n == k`.
    pub shard: [u64; 2],
    /// Passes written.
    pub passes: Vec<String>,
    /// `clevrtex` version.
    pub tool_version: String,
    /// Blender version of the samples (from their metadata).
    pub blender_version: String,
    /// The command line that made the run (rerunning it resumes and repairs).
    pub command: Vec<String>,
    /// Whether the run got to its end (`false`: only its plan, written before the first
    /// image; the run was interrupted or is still going). Absent in older manifests, which
    /// were only written at the end.
    #[serde(default = "finished_default")]
    pub finished: bool,
    /// Every file of the run's complete samples, by path relative to the variant folder.
    pub files: BTreeMap<String, FileEntry>,
    /// Seconds one worker spent on each complete sample, by stem: its visibility passes,
    /// rejected layouts, final render and writing (what `clevrtex report` plots). Kept from
    /// the previous manifest for samples an earlier run made; absent in older manifests.
    #[serde(default, skip_serializing_if = "BTreeMap::is_empty")]
    pub sample_seconds: BTreeMap<String, f64>,
}

/// xxh3-64 of `bytes` as 16 hex digits ([`clevrtex_materials::content_hash`], the one content
/// hash of the project).
pub fn hash_hex(bytes: &[u8]) -> String {
    format!("{:016x}", clevrtex_materials::content_hash(&[bytes]))
}

fn finished_default() -> bool {
    true
}

/// The manifest's file name for shard `k` of `n` of the indices `start..end`.
pub fn file_name(start: u64, end: u64, k: u64, n: u64) -> String {
    format!("MANIFEST-{start}-{end}-{k}of{n}.json")
}

/// Whether `name` is a manifest's file name (this version's or an older `MANIFEST-<k>of<n>.json`).
pub fn is_manifest_name(name: &str) -> bool {
    name.starts_with("MANIFEST-") && name.ends_with(".json")
}

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

impl Manifest {
    /// This manifest's file name ([`file_name`]).
    pub fn name(&self) -> String {
        file_name(self.start, self.end, self.shard[0], self.shard[1])
    }

    /// Write to `variant_dir/`[`Manifest::name`] through a temporary file and a rename.
    pub fn write(&self, variant_dir: &Path) -> Result<PathBuf> {
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

    /// Read a manifest file: a regular file (a link only within its folder), at most
    /// [`crate::dataset::MAX_FILE_BYTES`], whose values pass [`Manifest::check`].
    pub fn read(path: &Path) -> std::result::Result<Manifest, String> {
        let dir = path.parent().unwrap_or(Path::new("."));
        let root = crate::dataset::root(dir).map_err(|e| e.to_string())?;
        let bytes = crate::dataset::read(&root, path, crate::dataset::MAX_FILE_BYTES)?;
        let m: Manifest = serde_json::from_slice(&bytes).map_err(|e| e.to_string())?;
        if m.format != MANIFEST_FORMAT || m.version != MANIFEST_VERSION {
            return Err(format!(
                "not a version {MANIFEST_VERSION} clevrtex manifest (format `{}`, version {})",
                m.format, m.version
            ));
        }
        m.check()?;
        Ok(m)
    }

    /// The values that size or steer a reader, checked: `start <= end`, `end - start` at most
    /// [`MAX_RUN_INDICES`], `shard` `[k, n]` with `0 <= k < n`; the error names the key.
    pub fn check(&self) -> std::result::Result<(), String> {
        if self.start > self.end {
            return Err(format!(
                "key `start` ({}) is after `end` ({})",
                self.start, self.end
            ));
        }
        if self.end - self.start > MAX_RUN_INDICES {
            return Err(format!(
                "keys `start`..`end` ({}..{}) hold more than the {MAX_RUN_INDICES} indices a run may have",
                self.start, self.end
            ));
        }
        let [k, n] = self.shard;
        if n == 0 || k >= n {
            return Err(format!(
                "key `shard` is [{k}, {n}], not [k, n] with 0 <= k < n"
            ));
        }
        Ok(())
    }

    /// Whether `index` is one this manifest's run was asked to make.
    pub fn covers(&self, index: u64) -> bool {
        let [k, n] = self.shard;
        (self.start..self.end).contains(&index) && index % n.max(1) == k
    }

    /// The indices this manifest's run was asked to make.
    pub fn indices(&self) -> impl Iterator<Item = u64> {
        let [k, n] = self.shard;
        let n = n.max(1);
        let first = if self.start >= self.end {
            self.end
        } else {
            self.start + (k + n - self.start % n) % n
        };
        (first..self.end).step_by(n as usize)
    }
}

/// What a `generate` run records in its manifest, known before its first image: written as
/// its plan ([`Plan::write_plan`]) and, at the end, with the files it made ([`Plan::write`]).
#[derive(Debug, Clone)]
pub struct Plan {
    /// Variant name.
    pub variant: String,
    /// Run seed.
    pub seed: u64,
    /// xxh3 of the resolved variant config, hex ([`hash_hex`]).
    pub config_hash: String,
    /// First index of the run.
    pub start: u64,
    /// One past the last index (before sharding).
    pub end: u64,
    /// Size of the whole dataset.
    pub total: u64,
    /// This shard `[k, n]`.
    pub shard: [u64; 2],
    /// Passes written.
    pub passes: Vec<clevrtex_scene::Pass>,
    /// Whether the float EXRs are kept (they are files of the run too).
    pub keep_exr: bool,
    /// `clevrtex` version.
    pub tool_version: String,
    /// The command line that made the run.
    pub command: Vec<String>,
}

impl Plan {
    /// `OUT/clevrtex_<variant>/`.
    pub fn variant_dir(&self, out: &Path) -> PathBuf {
        clevrtex_scene::layout::variant_dir(out, &self.variant)
    }

    /// The manifest of this run's range and shard as an earlier run left it, if readable.
    fn earlier(&self, out: &Path) -> Option<Manifest> {
        let name = file_name(self.start, self.end, self.shard[0], self.shard[1]);
        Manifest::read(&self.variant_dir(out).join(name)).ok()
    }

    /// The manifest with these settings, `files` and `sample_seconds`.
    fn manifest(
        &self,
        finished: bool,
        blender_version: String,
        files: BTreeMap<String, FileEntry>,
        sample_seconds: BTreeMap<String, f64>,
    ) -> Manifest {
        Manifest {
            format: MANIFEST_FORMAT.into(),
            version: MANIFEST_VERSION,
            variant: self.variant.clone(),
            seed: self.seed,
            config_hash: self.config_hash.clone(),
            start: self.start,
            end: self.end,
            total: self.total,
            shard: self.shard,
            passes: self.passes.iter().map(|p| p.name().to_string()).collect(),
            tool_version: self.tool_version.clone(),
            blender_version,
            command: self.command.clone(),
            finished,
            files,
            sample_seconds,
        }
    }

    /// Write the run's plan into the (existing) variant folder before the first image: its
    /// manifest with `finished: false` and no files, so `verify` knows what the run is to
    /// make even if it never ends. The seconds of samples an earlier run of this range made
    /// are kept.
    pub fn write_plan(&self, out: &Path) -> Result<PathBuf> {
        let seconds = self
            .earlier(out)
            .map(|m| m.sample_seconds)
            .unwrap_or_default();
        let m = self.manifest(false, String::new(), BTreeMap::new(), seconds);
        m.write(&self.variant_dir(out))
    }

    /// Write the manifest of the run's complete samples (hashing their files).
    /// `seconds`: time per sample made by this run, by index; those of complete samples an
    /// earlier run made are kept from its manifest.
    pub fn write(&self, out: &Path, seconds: &BTreeMap<u64, f64>) -> Result<PathBuf> {
        use clevrtex_scene::layout;
        let vdir = self.variant_dir(out);
        let earlier = self
            .earlier(out)
            .map(|m| m.sample_seconds)
            .unwrap_or_default();
        let mut sample_seconds = BTreeMap::new();
        let mut files = Vec::new();
        let mut blender_version = String::new();
        let indices = self.manifest(true, String::new(), BTreeMap::new(), BTreeMap::new());
        for index in indices.indices() {
            let stem = layout::stem(&self.variant, index);
            let dir = layout::sample_dir(out, &self.variant, index);
            let names = crate::output::expected_files(&stem, &self.passes, self.keep_exr);
            if !names.iter().all(|n| dir.join(n).is_file()) {
                continue;
            }
            if blender_version.is_empty() {
                let meta =
                    std::fs::read(dir.join(layout::metadata_file(&stem))).unwrap_or_default();
                let meta: serde_json::Value = serde_json::from_slice(&meta).unwrap_or_default();
                blender_version = meta["blender_version"].as_str().unwrap_or("").to_string();
            }
            if let Some(s) = seconds.get(&index).or_else(|| earlier.get(&stem)) {
                sample_seconds.insert(stem.clone(), (s * 1000.0).round() / 1000.0);
            }
            let sub = (index / 1000).to_string();
            files.extend(names.into_iter().map(|n| format!("{sub}/{n}")));
        }
        let files = hash_files(&vdir, &files)?;
        let manifest = self.manifest(true, blender_version, files, sample_seconds);
        manifest.write(&vdir)
    }
}
