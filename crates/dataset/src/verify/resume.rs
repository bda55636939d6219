//! What a rerun of `generate` checks before it skips a sample as already complete
//! ([`ResumeCheck`]): the sample passes `verify`'s own check of one sample ([`check_sample`]:
//! its files hash as the finished manifest that lists them recorded, its metadata re-derives
//! from its run's seed and config, its mask agrees with its metadata), or it is made again. The
//! hashes of the files it accepted are kept, so the run's manifest records only hashes it
//! checked ([`crate::manifest::Plan::write`]).

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};
use std::sync::Mutex;

use clevrtex_scene::Pass;

use super::checks::check_sample;
use super::report::{Configs, Entries, Found, ReadManifest};
use crate::layout;
use crate::manifest::{FileEntry, Manifest};

/// A rerun's check of the samples it would skip, made from the folder's manifests as they
/// were before the run wrote its plan (which replaces its own range's manifest).
#[derive(Debug)]
pub struct ResumeCheck {
    variant: String,
    root: PathBuf,
    variant_dir: PathBuf,
    manifests: Vec<ReadManifest>,
    entries: Entries,
    configs: Configs,
    finished: Vec<usize>,
    checked: Mutex<BTreeMap<String, FileEntry>>,
    remade: Mutex<Vec<String>>,
}

impl ResumeCheck {
    /// The check of `variant`'s samples under `out` (the run's `--out`), from the manifests
    /// in its variant folder now. Unreadable manifests claim nothing.
    pub fn new(out: &Path, variant: &str) -> ResumeCheck {
        // Paths from the canonical root: every read is made beneath it.
        let root = crate::dataset::root(out).unwrap_or_else(|_| out.to_path_buf());
        let variant_dir = layout::variant_dir(&root, variant);
        let mut manifests = Vec::new();
        if let Ok(list) = crate::dataset::list(&root, &variant_dir) {
            for (name, path, kind) in list {
                if kind != crate::dataset::Kind::File || !crate::manifest::is_manifest_name(&name) {
                    continue;
                }
                if let Ok(m) = Manifest::read(&path) {
                    if m.variant == variant {
                        manifests.push((path, m, root.clone()));
                    }
                }
            }
        }
        let mut entries = Entries::default();
        let mut finished = Vec::new();
        for (i, (path, m, _)) in manifests.iter().enumerate() {
            if !m.finished {
                continue;
            }
            finished.push(i);
            entries.add(path, m);
        }
        let configs = manifests
            .iter()
            .map(|(p, m, _)| (p.clone(), super::rederive::config_of(m)))
            .collect();
        ResumeCheck {
            variant: variant.to_string(),
            root,
            variant_dir,
            manifests,
            entries,
            configs,
            finished,
            checked: Mutex::new(BTreeMap::new()),
            remade: Mutex::new(Vec::new()),
        }
    }

    /// Whether the sample `stem` (image `index`) in its folder of the layout, whose files of `passes` (and kept
    /// EXRs) all exist, may be skipped as complete: it passes `verify`'s check of one sample,
    /// and a manifest claims it. Its files' hashes are then kept for the manifest; otherwise
    /// why not is kept (for the run to say) and the sample is to be made again.
    pub fn intact(&self, index: u64, stem: &str, passes: &[Pass], keep_exr: bool) -> bool {
        let names = layout::expected_files(stem, passes, keep_exr);
        let claims: Vec<&ReadManifest> = self
            .manifests
            .iter()
            .filter(|(_, m, _)| m.covers(index))
            .collect();
        let refuse = |why: String| {
            self.remade
                .lock()
                .unwrap_or_else(|e| e.into_inner())
                .push(format!("{stem}: {why}"));
            false
        };
        if claims.is_empty() {
            return refuse("no manifest of this folder claims it: not made by a run here".into());
        }
        let listed = self
            .finished
            .iter()
            .any(|&i| self.manifests[i].1.covers(index));
        let splits_rule = layout::variant_splits(&claims[0].1.variant);
        let runs: Vec<(layout::Split, String)> = claims
            .iter()
            .map(|(p, m, _)| {
                (
                    layout::Split::of(splits_rule, index, m.total),
                    format!("the run of `{}`", p.display()),
                )
            })
            .collect();
        let found = Found {
            root: self.root.clone(),
            variant_dir: self.variant_dir.clone(),
            dir: layout::sample_dir(&self.root, &self.variant, index),
            files: names.iter().cloned().collect::<BTreeSet<String>>(),
        };
        let (_, result) = check_sample(
            index,
            stem,
            &found,
            &self.entries,
            listed,
            &claims,
            &self.configs,
            &runs,
        );
        if let Err(b) = result {
            return refuse(b.problems.join("; "));
        }
        let sub = (index / 1000).to_string();
        let rels: Vec<String> = names.iter().map(|n| format!("{sub}/{n}")).collect();
        match crate::manifest::hash_files(&self.variant_dir, &rels) {
            Ok(hashed) => {
                self.checked
                    .lock()
                    .unwrap_or_else(|e| e.into_inner())
                    .extend(hashed);
                true
            }
            Err(e) => refuse(e.to_string()),
        }
    }

    /// The files of the samples accepted as complete, with the hashes checked (paths relative
    /// to the variant folder).
    pub fn checked(&self) -> BTreeMap<String, FileEntry> {
        self.checked
            .lock()
            .unwrap_or_else(|e| e.into_inner())
            .clone()
    }

    /// The samples found with every file but made again, with why (one line each).
    pub fn remade(&self) -> Vec<String> {
        self.remade
            .lock()
            .unwrap_or_else(|e| e.into_inner())
            .clone()
    }
}
