//! The run manifest's writing side (its types and reading: [`crate::manifest::types`]): the
//! hashes of a run's files, and the atomic write of `MANIFEST-<start>-<end>-<k>of<n>.json`.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use rayon::prelude::*;

use super::types::*;

use crate::error::{Error, Result};

/// Size and hash of each of `files` (paths relative to `root`), in parallel.
pub fn hash_files(root: &Path, files: &[String]) -> Result<BTreeMap<String, FileEntry>> {
    files
        .par_iter()
        .map(|rel| {
            let path = root.join(rel);
            let bytes = std::fs::read(&path).map_err(|e| {
                Error::io(
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
                    xxh3: Xxh3::of(&bytes),
                },
            ))
        })
        .collect()
}

/// Writing a manifest (a trait: the type is the reading side's, [`crate::manifest::types`]).
pub trait WriteManifest {
    /// Write to `variant_dir/`[`Manifest::name`] with the one atomic writer
    /// ([`crate::atomic`]: no temporary is left on error, a full disk included).
    fn write(&self, variant_dir: &Path) -> Result<PathBuf>;
}

impl WriteManifest for Manifest {
    fn write(&self, variant_dir: &Path) -> Result<PathBuf> {
        let path = variant_dir.join(self.name());
        let text = serde_json::to_string_pretty(self).expect("manifest serialises") + "\n";
        crate::atomic::write(&path, text.as_bytes()).map_err(|e| Error::write(&path, e))?;
        Ok(path)
    }
}

/// What a `generate` run records in its manifest, known before its first image: written as
/// its plan ([`Plan::write_plan`]) and, at the end, with the files it made ([`Plan::write`]).
#[derive(Debug, Clone)]
pub struct Plan {
    /// The run's manifest as planned ([`Manifest::unfinished`] and the run's settings): the
    /// Blender, files and seconds are filled in when it is written.
    pub run: Manifest,
    /// Passes written.
    pub passes: Vec<clevrtex_scene::Pass>,
    /// Whether the float EXRs are kept (they are files of the run too).
    pub keep_exr: bool,
}

impl Plan {
    /// `OUT/clevrtex_<variant>/`.
    pub fn variant_dir(&self, out: &Path) -> PathBuf {
        crate::layout::variant_dir(out, &self.run.variant)
    }

    /// The manifest of this run's range and shard as an earlier run left it, if readable.
    fn earlier(&self, out: &Path) -> Option<Manifest> {
        Manifest::read(&self.variant_dir(out).join(self.run.name())).ok()
    }

    /// The manifest with these settings, `files` and `sample_seconds`.
    fn manifest(
        &self,
        finished: bool,
        blender_version: String,
        blender_compat: BTreeMap<String, serde_json::Value>,
        files: BTreeMap<String, FileEntry>,
        sample_seconds: BTreeMap<String, f64>,
    ) -> Manifest {
        Manifest {
            passes: self.passes.iter().map(|p| p.name().to_string()).collect(),
            blender_version,
            blender_compat,
            finished,
            files,
            sample_seconds,
            ..self.run.clone()
        }
    }

    /// Refuse a run into a folder whose manifests claim some of its indices with other
    /// settings (seed, passes, render settings, variant config): its samples would
    /// be skipped as complete and the folder would mix two datasets under one manifest. The
    /// error names the manifest and each setting that differs, with a hint. With `overwrite`
    /// the run re-renders every index of its range and shard, so its own manifest (same range
    /// and shard) is not compared; others still are.
    pub fn check_settings(&self, out: &Path, overwrite: bool) -> Result<()> {
        let vdir = self.variant_dir(out);
        let Ok(root) = crate::dataset::files::root(&vdir) else {
            return Ok(());
        };
        let Ok(entries) = crate::dataset::files::list(&root, &vdir) else {
            return Ok(());
        };
        let run = Manifest {
            passes: self.passes.iter().map(|p| p.name().to_string()).collect(),
            ..self.run.clone()
        };
        // `clevrtex sample`'s committed scene files have the names of the samples' metadata:
        // this run would replace them (`sample` refuses a folder of rendered samples alike).
        #[cfg(feature = "tools")]
        for (path, m) in crate::scene_files::manifests(&vdir) {
            if crate::run_lock::overlaps((m.start, m.end, m.shard), (run.start, run.end, run.shard))
            {
                return Err(Error::Refused(format!(
                    "`{}` commits scene files of indices {}..{} (written by `clevrtex sample`): rendering here would replace them with the samples' metadata files, which have their names\nhint: render them with `clevrtex render {} --out OTHER`, or pass another `--out` for this run",
                    path.display(),
                    m.start,
                    m.end,
                    out.display()
                )));
            }
        }
        for (name, path, kind) in entries {
            if kind != crate::dataset::files::Kind::File || !is_manifest_name(&name) {
                continue;
            }
            // An unreadable manifest is `verify`'s to report; it claims nothing here.
            let Ok(m) = Manifest::read(&path) else {
                continue;
            };
            if !run.overlaps(&m) || (overwrite && m.name() == run.name()) {
                continue;
            }
            let differ = m.settings_differ(&run);
            if !differ.is_empty() {
                return Err(Error::Refused(format!(
                    "`{}` was written by a run of indices {}..{} with other settings (that run vs this one: {}): rendering here would mix two datasets under one manifest\nhint: pass another `--out` for these settings, or rerun with the settings of that manifest (its `command`) to resume or repair it",
                    path.display(),
                    m.start,
                    m.end,
                    differ.iter().map(|d| clevrtex_scene::text::printable(d).into_owned()).collect::<Vec<_>>().join(", ")
                )));
            }
        }
        Ok(())
    }

    /// Refuse, before anything is made or written, a run whose `--total` differs from that of
    /// a run already in the folder (under the split rule `rule`; a test-only variant has one
    /// split whatever the total): each image records the split of its run's total, so the
    /// grown dataset's recorded splits would differ from the public loader's position rule
    /// over all its images, and `clevrtex eval --split test` and the public evaluator would
    /// score other test sets. `allow` (`--allow-split-mismatch`) renders anyway; `verify`,
    /// `report` and the card then say where the splits differ. A run of the same range, shard
    /// and total as one already recorded (the same command again) is never refused.
    pub fn check_splits(
        &self,
        out: &Path,
        rule: clevrtex_scene::names::Splits,
        allow: bool,
    ) -> Result<()> {
        if allow || rule == clevrtex_scene::names::Splits::TestOnly {
            return Ok(());
        }
        let total = self.run.total;
        // The same range, shard and total as a run already in the folder: that run again (a
        // resume, or a repair of a complete range), never refused, whatever other runs hold.
        if self.earlier(out).is_some_and(|m| m.total == total) {
            return Ok(());
        }
        let vdir = self.variant_dir(out);
        let Ok(root) = crate::dataset::files::root(&vdir) else {
            return Ok(());
        };
        let Ok(entries) = crate::dataset::files::list(&root, &vdir) else {
            return Ok(());
        };
        for (name, path, kind) in entries {
            if kind != crate::dataset::files::Kind::File || !is_manifest_name(&name) {
                continue;
            }
            let Ok(m) = Manifest::read(&path) else {
                continue;
            };
            if m.variant != self.run.variant || m.total == total {
                continue;
            }
            return Err(Error::Refused(format!(
                "`{}` records a run of indices {}..{} for a dataset of {} images, and this run's total is {total}: each image records the split of its run's total, so the dataset's splits would differ from the public loader's position rule (test the first int(0.1 N) of all N images, val the next) and `clevrtex eval --split test` and the public evaluator would score other test sets\nhint: pass `--total {}` as the earlier runs did (the same `--total` for every run of a dataset), or make a dataset of {total} images in a new `--out` folder; `--allow-split-mismatch` renders anyway",
                path.display(),
                m.start,
                m.end,
                m.total,
                m.total
            )));
        }
        Ok(())
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
        let m = self.manifest(
            false,
            String::new(),
            BTreeMap::new(),
            BTreeMap::new(),
            seconds,
        );
        m.write(&self.variant_dir(out))
    }

    /// Write the manifest of the run's complete samples (hashing their files).
    /// `seconds`: time per sample made by this run, by index; those of complete samples an
    /// earlier run made are kept from its manifest. Every index of the run is checked again
    /// on disk: one that is neither complete nor in `failed` (this run's failures, in its
    /// ledger) lost its files after it was written or skipped as complete (deleted by
    /// another process): the manifest is then written unfinished and `Err` names those
    /// indices, so the run never calls a dataset finished that is not. `stop` (Ctrl-C, SIGTERM)
    /// is checked at every index: `Err` when raised, nothing written. `checked`: the files of
    /// the samples the run skipped as complete, with the hashes it checked them at
    /// ([`crate::verify::ResumeCheck`]); a skipped sample whose files now hash otherwise (or
    /// that was not checked) is not recorded: the manifest records no hash the run did not
    /// check, and is written unfinished.
    pub fn write(
        &self,
        out: &Path,
        seconds: &BTreeMap<u64, f64>,
        failed: &std::collections::BTreeSet<u64>,
        stop: &std::sync::atomic::AtomicBool,
        checked: Option<&BTreeMap<String, FileEntry>>,
    ) -> Result<PathBuf> {
        use crate::layout;
        let vdir = self.variant_dir(out);
        let earlier = self
            .earlier(out)
            .map(|m| m.sample_seconds)
            .unwrap_or_default();
        let mut sample_seconds = BTreeMap::new();
        let mut files = Vec::new();
        let mut blender_version = String::new();
        let mut blender_compat = BTreeMap::new();
        let mut lost = Vec::new();
        let mut changed = Vec::new();
        for index in self.run.indices() {
            if stop.load(std::sync::atomic::Ordering::Relaxed) {
                return Err(Error::Refused(
                    "interrupted while the manifest was written; nothing was written\nhint: rerun the same command: complete samples are skipped and the manifest is written".into(),
                ));
            }
            let stem = layout::stem(&self.run.variant, index);
            let dir = layout::sample_dir(out, &self.run.variant, index);
            let names = crate::layout::expected_files(&stem, &self.passes, self.keep_exr);
            if !names.iter().all(|n| dir.join(n).is_file()) {
                if !failed.contains(&index) {
                    lost.push(index);
                }
                continue;
            }
            if blender_version.is_empty() {
                let meta =
                    std::fs::read(dir.join(layout::metadata_file(&stem))).unwrap_or_default();
                let meta: serde_json::Value = serde_json::from_slice(&meta).unwrap_or_default();
                blender_version = meta["blender_version"].as_str().unwrap_or("").to_string();
                if let Some(c) = meta["blender_compat"].as_object() {
                    blender_compat = c.clone().into_iter().collect();
                }
            }
            if let Some(s) = seconds.get(&index).or_else(|| earlier.get(&stem)) {
                sample_seconds.insert(stem.clone(), (s * 1000.0).round() / 1000.0);
            }
            let sub = (index / 1000).to_string();
            files.extend(names.into_iter().map(|n| format!("{sub}/{n}")));
        }
        let mut files = hash_files(&vdir, &files)?;
        if let Some(checked) = checked {
            // A sample this run did not make (not in `seconds`) is recorded only with the
            // hashes it was checked at when it was skipped.
            let mut unchecked = std::collections::BTreeSet::new();
            for (rel, e) in &files {
                let name = rel.rsplit('/').next().unwrap_or(rel);
                let Some((_, _, index)) = layout::parse_file_name(name) else {
                    continue;
                };
                if !seconds.contains_key(&index) && checked.get(rel) != Some(e) {
                    unchecked.insert(index);
                }
            }
            files.retain(|rel, _| {
                let name = rel.rsplit('/').next().unwrap_or(rel);
                layout::parse_file_name(name).is_none_or(|(_, _, i)| !unchecked.contains(&i))
            });
            sample_seconds.retain(|stem, _| {
                layout::parse_stem(stem, "").is_none_or(|(_, _, i)| !unchecked.contains(&i))
            });
            changed.extend(unchecked);
        }
        let finished = lost.is_empty() && changed.is_empty();
        let manifest = self.manifest(
            finished,
            blender_version,
            blender_compat,
            files,
            sample_seconds,
        );
        let path = manifest.write(&vdir)?;
        if !changed.is_empty() {
            let shown: Vec<String> = changed.iter().take(20).map(ToString::to_string).collect();
            return Err(Error::Refused(format!(
                "{} sample(s) this run skipped as complete are not what it checked (index {}{}): their files changed after the check, or were never checked; the manifest `{}` records none of them and is written as unfinished\nhint: rerun the same command to check them again (a sample that fails the check is made again), then check with `clevrtex verify`",
                changed.len(),
                shown.join(", "),
                if changed.len() > 20 { ", ..." } else { "" },
                path.display()
            )));
        }
        if !finished {
            let shown: Vec<String> = lost.iter().take(20).map(ToString::to_string).collect();
            return Err(Error::Refused(format!(
                "{} sample(s) of this run are gone from `{}` since they were written or found complete (index {}{}): another process removed their files while the run was going (e.g. `clevrtex verify --remove-broken` of an older version, or a cleanup); the manifest `{}` is written as unfinished\nhint: rerun the same command to make them again (complete samples are skipped), then check with `clevrtex verify`",
                lost.len(),
                vdir.display(),
                shown.join(", "),
                if lost.len() > 20 { ", ..." } else { "" },
                path.display()
            )));
        }
        Ok(path)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use clevrtex_scene::names::Splits;

    fn plan(start: u64, end: u64, total: u64) -> Plan {
        Plan {
            run: Manifest {
                variant: "camo".into(),
                start,
                end,
                total,
                ..Manifest::unfinished()
            },
            passes: Vec::new(),
            keep_exr: false,
        }
    }

    /// Issue 48: a sample the run did not make is recorded only with the hashes it was
    /// checked at; one whose bytes changed since (or that was never checked) is left out and
    /// the manifest is unfinished.
    #[test]
    fn the_manifest_records_no_hash_the_run_did_not_check() {
        let dir = tempfile::tempdir().unwrap();
        let out = dir.path();
        let mut p = plan(0, 1, 1);
        p.passes = vec![clevrtex_scene::Pass::Mask];
        let sub = p.variant_dir(out).join("0");
        std::fs::create_dir_all(&sub).unwrap();
        let stem = crate::layout::stem("camo", 0);
        let names = crate::layout::expected_files(&stem, &p.passes, false);
        for n in &names {
            std::fs::write(sub.join(n), b"checked").unwrap();
        }
        let rels: Vec<String> = names.iter().map(|n| format!("0/{n}")).collect();
        let checked = hash_files(&p.variant_dir(out), &rels).unwrap();
        let none = (BTreeMap::new(), std::collections::BTreeSet::new());
        let stop = std::sync::atomic::AtomicBool::new(false);
        let path = p
            .write(out, &none.0, &none.1, &stop, Some(&checked))
            .unwrap();
        assert_eq!(Manifest::read(&path).unwrap().files, checked);
        // A file changed after the check: not recorded, unfinished.
        std::fs::write(sub.join(&names[0]), b"changed").unwrap();
        let e = p
            .write(out, &none.0, &none.1, &stop, Some(&checked))
            .unwrap_err();
        assert!(
            e.to_string().contains("not what it checked (index 0)"),
            "{e}"
        );
        let m = Manifest::read(&path).unwrap();
        assert!(!m.finished && m.files.is_empty(), "{m:?}");
    }

    /// Issue 41: growing with another `--total` is refused, but the same command again (the
    /// first run's, or the grown run's) never is, even in a folder grown on purpose.
    #[test]
    fn the_same_command_again_is_never_refused_by_the_split_check() {
        let dir = tempfile::tempdir().unwrap();
        let out = dir.path();
        let (first, grown) = (plan(0, 12, 12), plan(12, 20, 20));
        std::fs::create_dir_all(first.variant_dir(out)).unwrap();
        first.write_plan(out).unwrap();
        let e = grown
            .check_splits(out, Splits::Standard, false)
            .unwrap_err();
        assert!(e.to_string().contains("pass `--total 12`"), "{e}");
        grown.check_splits(out, Splits::Standard, true).unwrap();
        grown.write_plan(out).unwrap();
        // Both runs again: resumes or repairs of their own ranges.
        first.check_splits(out, Splits::Standard, false).unwrap();
        grown.check_splits(out, Splits::Standard, false).unwrap();
        // A new range with the first run's total is still refused (the grown run differs).
        let e = plan(0, 4, 12)
            .check_splits(out, Splits::Standard, false)
            .unwrap_err();
        assert!(e.to_string().contains("this run's total is 12"), "{e}");
        // A test-only variant has one split whatever the total.
        plan(0, 4, 4)
            .check_splits(out, Splits::TestOnly, false)
            .unwrap();
    }
}
