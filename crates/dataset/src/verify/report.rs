//! What `verify` reports: per variant ([`VariantReport`]), each broken sample ([`Broken`]).

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};

use serde::Serialize;

use crate::manifest::{FileEntry, Manifest};

/// One sample found on disk: its files by name, and the folder they are in.
#[derive(Debug, Clone)]
pub(super) struct Found {
    /// The dataset root it was found under (canonical), which no link may leave.
    pub(super) root: PathBuf,
    /// Variant folder the sample is under (`.../clevrtex_<variant>`).
    pub(super) variant_dir: PathBuf,
    /// The sample's folder.
    pub(super) dir: PathBuf,
    /// File names in `dir` that belong to the stem.
    pub(super) files: BTreeSet<String>,
}

/// A broken sample and why.
#[derive(Debug, Clone, Serialize)]
pub struct Broken {
    /// Image index.
    pub index: u64,
    /// File stem.
    pub stem: String,
    /// The sample's folder.
    pub dir: PathBuf,
    /// What is wrong, one line each.
    pub problems: Vec<String>,
    /// Whether a run of the manifests covers the index, so rerunning its command remakes the
    /// sample: only such samples are removed by `--remove-broken`.
    pub rerun_remakes: bool,
}

/// The most missing indices listed one by one (all are counted in `missing_count`).
pub const MAX_LISTED: usize = 1_000_000;

/// What `verify` found for one variant.
#[derive(Debug, Clone, Default, Serialize)]
pub struct VariantReport {
    /// Variant name.
    pub variant: String,
    /// Indices the run was to make (the union of the manifests' ranges, else `0..=max found`).
    pub expected: u64,
    /// Where the expected indices came from.
    pub expected_from: String,
    /// Complete, intact samples.
    pub ok: u64,
    /// Expected indices with no sample (the first [`MAX_LISTED`]).
    pub missing: Vec<u64>,
    /// How many expected indices have no sample.
    pub missing_count: u64,
    /// Indices found more than once, with each place (folder and stem: `0000001` and
    /// `000001` are both index 1).
    pub duplicates: BTreeMap<u64, Vec<PathBuf>>,
    /// Samples found but broken.
    pub broken: Vec<Broken>,
    /// Samples whose index the run did not ask for.
    pub unexpected: Vec<u64>,
    /// Temporary files (of killed runs, and of live ones: [`crate::atomic::tagged_name_is_stale`]
    /// tells them apart).
    pub temp_files: Vec<PathBuf>,
    /// Entries not followed or not read: links leading out of the dataset, FIFOs, devices,
    /// files over the size cap (one line each, naming the path).
    pub skipped: Vec<String>,
    /// Manifests read.
    pub manifests: Vec<PathBuf>,
    /// Problems with the manifests themselves (unreadable, runs that did not finish, shards
    /// that disagree or lack one).
    pub manifest_problems: Vec<String>,
    /// Entries of the failure ledgers: index -> error.
    pub ledger: BTreeMap<u64, String>,
    /// Each split's samples (of those found once) as index ranges `[first, last]`, by the one
    /// split rule of every reader ([`crate::dataset::splits()`]: the recorded `split`, else by position).
    pub splits: BTreeMap<String, Vec<[u64; 2]>>,
    /// Where those splits differ from the public loader's position rule over the samples
    /// found ([`crate::dataset::loader_disagreement`]), one sentence; absent when they agree
    /// (or an index is missing: the loader refuses gaps). Not a broken sample: the dataset
    /// is whole, but the public evaluator would score another test set than `clevrtex eval`.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub loader_splits: Option<String>,
    /// Commands to rerun after repair: those of the runs (from the manifests) whose indices
    /// are missing or broken or that did not finish, with `--out` set to the folder verified.
    pub commands: Vec<Vec<String>>,
    /// The user materials (`--materials DIR`) the runs drew from, by name, as their manifests
    /// record them (file, group, textures, content hash); two runs recording one name with
    /// different contents is a manifest problem. Left out of the JSON when empty.
    #[serde(skip_serializing_if = "BTreeMap::is_empty")]
    pub user_materials: BTreeMap<String, crate::manifest::UserMaterial>,
    /// Runs whose settings differ from the first run's where one of them was made with
    /// `generate --mix-settings` (mixed on purpose: named, not a problem); one line each.
    /// Left out of the JSON when empty.
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub mixed_on_purpose: Vec<String>,
    /// Runs whose samples' layouts were not drawn again (their config cannot be rebuilt from
    /// the manifest: a `--config` file, user materials), one line each naming the manifest:
    /// their samples are checked against the manifest's hashes and settings only. Left out of
    /// the JSON when empty.
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub not_rederived: Vec<String>,
    /// Samples whose layout was drawn again from their run's seed and config and found equal
    /// to their metadata.
    pub rederived: u64,
    /// The canonical roots of the datasets the variant was found in: what every delete of
    /// [`super::remove_broken`] is made relative to.
    #[serde(skip)]
    pub roots: Vec<PathBuf>,
    /// The variant folders read (`clevrtex_<variant>` of each dataset): where
    /// [`super::remove_broken`] reads the range locks of live runs.
    #[serde(skip)]
    pub variant_dirs: Vec<PathBuf>,
}

impl VariantReport {
    /// Whether the variant is whole: every expected index once, intact, no temporary files,
    /// nothing skipped, no manifest problems (every planned run finished).
    pub fn is_whole(&self) -> bool {
        self.missing_count == 0
            && self.duplicates.is_empty()
            && self.broken.is_empty()
            && self.temp_files.is_empty()
            && self.skipped.is_empty()
            && self.manifest_problems.is_empty()
    }
}

/// Options of a verification.
#[derive(Debug, Clone, Default)]
pub struct VerifyOptions {
    /// Only this variant.
    pub variant: Option<String>,
}

/// A manifest read: its path, its contents and the folder its run's rerun writes into.
pub(super) type ReadManifest = (PathBuf, Manifest, PathBuf);

/// The config of each manifest's run rebuilt from its settings (by the manifest's path), or
/// why it cannot be ([`super::rederive::config_of`]).
pub(super) type Configs = BTreeMap<PathBuf, Result<clevrtex_scene::Config, String>>;

/// Manifest entries by variant folder and stem: each file name with the entries of every
/// finished manifest that lists it (a later run with `--overwrite` may have changed the
/// bytes). Kept compact (a list per sample, names once each), so a manifest of a million
/// files costs about its size in memory again, not several times it.
#[derive(Debug, Default)]
pub(super) struct Entries {
    dirs: Vec<(PathBuf, BTreeMap<Box<str>, SampleEntries>)>,
}

/// One sample's manifest entries: (file name, entry), sorted by name, a name's entries in the
/// order their manifests were added.
#[derive(Debug, Default)]
pub(super) struct SampleEntries(Vec<(Box<str>, FileEntry)>);

impl Entries {
    /// The entries of the sample `stem` of the variant folder `variant_dir`.
    pub(super) fn get(&self, variant_dir: &Path, stem: &str) -> Option<&SampleEntries> {
        let (_, samples) = self.dirs.iter().find(|(d, _)| d == variant_dir)?;
        samples.get(stem)
    }

    /// Add the files that the manifest `m` (read from `path`) records, under its variant
    /// folder and each file's stem (names that are no sample's file are left out).
    pub(super) fn add(&mut self, path: &Path, m: &crate::manifest::Manifest) {
        let vdir = path.parent().unwrap_or(Path::new("."));
        let at = match self.dirs.iter().position(|(d, _)| d == vdir) {
            Some(at) => at,
            None => {
                self.dirs.push((vdir.to_path_buf(), BTreeMap::new()));
                self.dirs.len() - 1
            }
        };
        let samples = &mut self.dirs[at].1;
        for (rel, e) in &m.files {
            let name = rel.rsplit('/').next().unwrap_or(rel);
            if let Some((stem, _, _)) = crate::layout::parse_file_name(name) {
                let list = &mut samples.entry(stem.into()).or_default().0;
                let after = list.partition_point(|(n, _)| **n <= *name);
                list.insert(after, (name.into(), *e));
            }
        }
    }
}

impl SampleEntries {
    /// The entries of the file `name` (at least one), or `None` when no manifest lists it.
    pub(super) fn get(&self, name: &str) -> Option<&[(Box<str>, FileEntry)]> {
        let from = self.0.partition_point(|(n, _)| **n < *name);
        let to = self.0.partition_point(|(n, _)| **n <= *name);
        (from < to).then(|| &self.0[from..to])
    }

    /// The file names listed, each once, sorted.
    pub(super) fn names(&self) -> impl Iterator<Item = &str> {
        let mut last: Option<&str> = None;
        self.0.iter().filter_map(move |(n, _)| {
            let new = last != Some(&**n);
            last = Some(n);
            new.then_some(&**n)
        })
    }
}
