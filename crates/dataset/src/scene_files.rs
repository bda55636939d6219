//! Scene files as `clevrtex sample` writes them: each through the atomic writer without a
//! sync of its own ([`write`]: readers see a whole file or none), made durable once at the end
//! of the run and committed by the manifest of the range sampled ([`commit`]:
//! `SCENES-<start>-<end>-<k>of<n>.manifest` in the variant folder, written and synced last).
//! A folder without the manifest of a range may hold files of an interrupted or crashed run
//! (whole, but after a power loss possibly empty or missing): rerunning the same command
//! rewrites every file and commits them. The manifest's name does not end in `.json`, so
//! `clevrtex render DIR` never takes it for a scene file.
//!
//! A run is a writer like `generate` (under the range's lock, `crate::run_lock`): before
//! anything is replaced, [`check_folder`] refuses a folder of rendered samples (their metadata
//! files have the scene files' names) and a run over scene files another run wrote (another
//! seed, stream, config or `--total`), and [`invalidate`] removes the range's own commit, so a
//! kill while files are rewritten leaves them uncommitted. [`uncommitted`] tells `render` which
//! files no manifest commits.

use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

use crate::atomic;
use crate::dataset::files;
use clevrtex_scene::text::printable;

/// The largest scene-files manifest read (one is a few hundred bytes).
const MAX_MANIFEST_BYTES: u64 = 64 * 1024;

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

    /// Whether the run made `index` (its range and shard).
    pub fn covers(&self, index: u64) -> bool {
        (self.start..self.end).contains(&index) && index % self.shard[1].max(1) == self.shard[0]
    }

    /// Whether some index is made by both runs.
    fn overlaps(&self, other: &ScenesManifest) -> bool {
        crate::run_lock::overlaps(
            (self.start, self.end, self.shard),
            (other.start, other.end, other.shard),
        )
    }
}

/// The scene-files manifests of `variant_dir` (each read capped and parsed), with their paths;
/// one that cannot be read is left out (it commits nothing).
pub fn manifests(variant_dir: &Path) -> Vec<(PathBuf, ScenesManifest)> {
    let Ok(root) = files::root(variant_dir) else {
        return Vec::new();
    };
    let mut found = Vec::new();
    for (name, path, kind) in files::list(&root, variant_dir).unwrap_or_default() {
        if kind != files::Kind::File || !(name.starts_with("SCENES-") && name.ends_with(SUFFIX)) {
            continue;
        }
        let m = files::read(&root, &path, MAX_MANIFEST_BYTES)
            .and_then(|b| serde_json::from_slice::<ScenesManifest>(&b).map_err(|e| e.to_string()));
        if let Some(m) = m.ok().filter(|m| m.format == FORMAT && m.name() == name) {
            found.push((path, m));
        }
    }
    found
}

/// Refuse, before anything is written, to sample `run` into `variant_dir` (an existing
/// variant folder, held under the range's lock) when the folder holds rendered samples (a
/// `generate` manifest: sample's files would replace their metadata files, which have the
/// same names) or a scene-files manifest of another `--total`, or of another seed or layout
/// stream over indices of this run. The message names the file and says what to do.
pub fn check_folder(variant_dir: &Path, run: &ScenesManifest) -> Result<(), String> {
    let root = files::root(variant_dir)
        .map_err(|e| format!("cannot read `{}`: {e}", variant_dir.display()))?;
    for (name, path, _) in files::list(&root, variant_dir).unwrap_or_default() {
        if crate::manifest::is_manifest_name(&name) {
            return Err(rendered_here(variant_dir, &path));
        }
    }
    for (path, m) in manifests(variant_dir) {
        let mut differ = Vec::new();
        // As `generate`: another total changes the recorded splits (never a test-only
        // variant's).
        let test_only =
            crate::layout::variant_splits(&run.variant) == clevrtex_scene::names::Splits::TestOnly;
        if m.total != run.total && !test_only {
            differ.push(format!("--total {} vs {}", m.total, run.total));
        }
        if m.overlaps(run) {
            if m.seed != run.seed {
                differ.push(format!("--seed {} vs {}", m.seed, run.seed));
            }
            if m.layout_stream != run.layout_stream {
                differ.push(format!(
                    "--layout-stream {} vs {}",
                    printable(&m.layout_stream),
                    run.layout_stream
                ));
            }
        }
        if !differ.is_empty() {
            return Err(format!(
                "`{}` commits scene files of indices {}..{} sampled with other settings (that run vs this one: {}): sampling here would mix two sets of scenes\nhint: pass another `--out` for these settings, or rerun with the settings of that run",
                path.display(),
                m.start,
                m.end,
                differ.join(", ")
            ));
        }
    }
    Ok(())
}

/// Refuse, before anything is made, to sample `variant` into `out` when `out` is a dataset:
/// another variant's folder holds a `generate` manifest, or `out` holds a suite's
/// `SUITE.json`. Scene files beside a dataset's variants would make `verify` of it fail (they
/// read as unfinished samples) and offer to remove them. This variant's own folder is
/// [`check_folder`]'s.
pub fn check_out(out: &Path, variant: &str) -> Result<(), String> {
    if !out.is_dir() {
        return Ok(());
    }
    let root = files::root(out).map_err(|e| format!("cannot read `{}`: {e}", out.display()))?;
    let own = crate::layout::variant_dir(out, variant);
    for (name, path, kind) in files::list(&root, out).unwrap_or_default() {
        if name == crate::suite::SUITE_FILE {
            return Err(dataset_here(out, &path));
        }
        if !name.starts_with("clevrtex_") || path == own || !matches!(kind, files::Kind::Dir) {
            continue;
        }
        for (inner, found, _) in files::list(&root, &path).unwrap_or_default() {
            if crate::manifest::is_manifest_name(&inner) {
                return Err(dataset_here(out, &found));
            }
        }
    }
    Ok(())
}

fn dataset_here(out: &Path, found: &Path) -> String {
    format!(
        "`{}` is a dataset (`{}`): scene files written beside its variants would make `clevrtex verify` of it fail\nhint: pass another `--out` for scene files (`clevrtex render` reads them from there)",
        out.display(),
        printable(&found.display().to_string())
    )
}

/// The refusal of a folder holding rendered samples (`found` one of their files).
pub fn rendered_here(variant_dir: &Path, found: &Path) -> String {
    format!(
        "`{}` holds rendered samples (`{}`): `clevrtex sample` would replace their metadata files, which have the scene files' names\nhint: pass another `--out` for scene files (`clevrtex render` reads them from there)",
        variant_dir.display(),
        found.display()
    )
}

/// The files of the layout named `CLEVRTEX_<variant>_<index>.json` under `out` that `run`
/// would write (its range and shard), by index: what a run replaces, checked before it starts.
pub fn existing(out: &Path, run: &ScenesManifest) -> Result<Vec<(u64, PathBuf)>, String> {
    let vdir = crate::layout::variant_dir(out, &run.variant);
    let root = files::root(&vdir).map_err(|e| format!("cannot read `{}`: {e}", vdir.display()))?;
    let mut found = Vec::new();
    if run.start >= run.end {
        return Ok(found);
    }
    for bucket in run.start / 1000..=(run.end - 1) / 1000 {
        let dir = crate::layout::sample_dir(out, &run.variant, bucket * 1000);
        if files::classify(&root, &dir) != files::Kind::Dir {
            continue;
        }
        for (name, path, _) in files::list(&root, &dir).unwrap_or_default() {
            if let Some((_, v, index)) = crate::layout::parse_stem(&name, ".json") {
                if v == run.variant && run.covers(index) {
                    found.push((index, path));
                }
            }
        }
    }
    Ok(found)
}

/// Remove the commit of `run`'s own range and shard from `variant_dir` (a rerun of it), made
/// durable before any file is replaced: a kill while the run rewrites its files then leaves
/// them uncommitted, never committed by a manifest of other bytes.
pub fn invalidate(variant_dir: &Path, run: &ScenesManifest) -> std::io::Result<()> {
    let path = variant_dir.join(run.name());
    match std::fs::remove_file(&path) {
        Ok(()) => std::fs::File::open(variant_dir)?.sync_all(),
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => Ok(()),
        Err(e) => Err(e),
    }
}

/// Of `scene_files` (paths of the layout, `OUT/clevrtex_<v>/<bucket>/CLEVRTEX_<v>_<i>.json`),
/// those no scene-files manifest of their variant folder commits, counted by variant folder:
/// files of a killed or running `clevrtex sample` (whole, but after a power loss possibly
/// empty), or written by something else. Files outside the layout are not counted.
pub fn uncommitted(scene_files: &[PathBuf]) -> Vec<(PathBuf, u64)> {
    let mut by_dir: std::collections::BTreeMap<PathBuf, (Vec<ScenesManifest>, u64)> =
        Default::default();
    for f in scene_files {
        let name = f.file_name().map(|n| n.to_string_lossy().into_owned());
        let Some((_, variant, index)) = name
            .as_deref()
            .and_then(|n| crate::layout::parse_stem(n, ".json"))
        else {
            continue;
        };
        let Some(vdir) = f.parent().and_then(Path::parent) else {
            continue;
        };
        if vdir
            .file_name()
            .is_none_or(|n| n.to_string_lossy() != format!("clevrtex_{variant}"))
        {
            continue;
        }
        let entry = by_dir
            .entry(vdir.to_path_buf())
            .or_insert_with(|| (manifests(vdir).into_iter().map(|(_, m)| m).collect(), 0));
        if !entry
            .0
            .iter()
            .any(|m| m.variant == variant && m.covers(index))
        {
            entry.1 += 1;
        }
    }
    by_dir
        .into_iter()
        .filter(|(_, (_, n))| *n > 0)
        .map(|(d, (_, n))| (d, n))
        .collect()
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
