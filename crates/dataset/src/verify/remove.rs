//! `verify --remove-broken`: deleting the files of broken samples a rerun remakes, relative to
//! a handle on the dataset's root (no link out followed).

use std::path::Path;

use clevrtex_scene::Pass;

use crate::dataset::{self};
use crate::layout::{self, TMP_SUFFIX};
use crate::run_lock::{Holder, Quiet};

use super::report::*;

/// What [`remove_broken`] did.
#[derive(Debug, Clone, Default)]
pub struct Removal {
    /// Files removed.
    pub files: usize,
    /// Broken samples kept because no run of the manifests covers them (no known command
    /// remakes them).
    pub kept: Vec<u64>,
    /// Samples left alone because a live run is writing them (in the range of its lock), with
    /// that run ([`Holder::describe`]): what looks unfinished may be a sample being written.
    pub live: Vec<(u64, String)>,
    /// Temporary files left alone because their owner runs (on this host) or may run (on
    /// another host).
    pub live_temps: usize,
}

/// Remove the files of each broken sample that a rerun of a manifest's run remakes
/// ([`Broken::rerun_remakes`]; metadata first, so an interrupted removal still leaves the
/// sample incomplete), and the temporary files of dead writers. A live run's files are never
/// touched: each variant folder is held still ([`Quiet`]: no run can start meanwhile) and a
/// sample whose index is in the range lock of a live run is left alone, as is a temporary
/// whose owner tag names a live process (or another host). Only names of the layout
/// (every pass, the metadata, the EXRs) are removed, in the sample's folder found inside the
/// dataset, and a link is removed as a link (its target is never touched). Each folder is
/// opened once relative to its dataset's root ([`dataset::open_dir_beneath`]) and every
/// delete is made relative to that handle (`unlinkat`): a folder swapped for a link leading
/// out of the dataset while this runs is refused, nothing outside is deleted. Duplicates are
/// only reported.
pub fn remove_broken(report: &VariantReport) -> std::io::Result<Removal> {
    remove_broken_with(report, &mut |_| {})
}

/// [`remove_broken`], calling `before_open` with each folder before it is opened (tests swap a
/// folder for a link there).
pub fn remove_broken_with(
    report: &VariantReport,
    before_open: &mut dyn FnMut(&Path),
) -> std::io::Result<Removal> {
    let mut out = Removal::default();
    let open = |dir: &Path| {
        dataset::open_dir_beneath(&report.roots, dir).map_err(|e| {
            if dataset::is_leads_out(&e) {
                std::io::Error::other(format!(
                    "`{}` leads out of the dataset through a symbolic link (swapped since it was checked?); nothing removed there\nhint: check what replaced that folder, then run `clevrtex verify --remove-broken` again",
                    dir.display()
                ))
            } else {
                e
            }
        })
    };
    // Held for the whole removal: the live runs of each variant folder, none starting meanwhile.
    let mut held: Vec<(&Path, Quiet)> = Vec::new();
    if !report.broken.is_empty() || !report.temp_files.is_empty() {
        for vd in &report.variant_dirs {
            let quiet = Quiet::hold(vd).map_err(std::io::Error::other)?;
            held.push((vd.as_path(), quiet));
        }
    }
    let writer_of = |dir: &Path, index: u64| -> Option<&Holder> {
        held.iter()
            .filter(|(vd, _)| dir.starts_with(vd))
            .find_map(|(_, q)| q.writer_of(index))
    };
    for b in &report.broken {
        if let Some(h) = writer_of(&b.dir, b.index) {
            out.live.push((b.index, h.describe()));
            continue;
        }
        if !b.rerun_remakes {
            out.kept.push(b.index);
            continue;
        }
        let mut names = vec![layout::metadata_file(&b.stem)];
        names.extend(crate::layout::expected_files(&b.stem, &Pass::ALL, true));
        names.extend(layout::legacy_exr_files(&b.stem));
        names.dedup();
        before_open(&b.dir);
        let (_, handle) = open(&b.dir)?;
        for name in names {
            if dataset::remove_beneath(&handle, &name)? {
                out.files += 1;
            }
        }
    }
    for t in &report.temp_files {
        let name = t
            .file_name()
            .map(|n| n.to_string_lossy().into_owned())
            .unwrap_or_default();
        // A live writer's temporary (another shard writing now) is not stray.
        let live = name
            .strip_suffix(TMP_SUFFIX)
            .is_some_and(|stem| !crate::atomic::tagged_name_is_stale(stem));
        if live {
            out.live_temps += 1;
            continue;
        }
        let Some(dir) = t.parent() else { continue };
        before_open(dir);
        if let Ok((_, handle)) = open(dir) {
            if dataset::remove_beneath(&handle, &name).unwrap_or(false) {
                out.files += 1;
            }
        }
    }
    Ok(out)
}
