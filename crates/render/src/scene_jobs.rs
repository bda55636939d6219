//! The jobs of a run with its failure ledger and the materials it uses ([`RunJobs`]):
//! `render`'s fixed scene files ([`of_scene_files`]); `generate`'s are `crate::generate`'s.

use std::collections::BTreeSet;
use std::path::{Path, PathBuf};
use std::sync::Arc;

use clevrtex_dataset::layout;
use clevrtex_materials::Catalogue;
use clevrtex_scene::Pass;

use crate::pool::{Job, Jobs};
use crate::{RenderError, Result};

/// What a run renders: its jobs, its failure ledger, the materials its scenes use.
pub struct RunJobs {
    /// The jobs.
    pub jobs: Jobs,
    /// The failure ledger.
    pub ledger: PathBuf,
    /// Every material the scenes use (the user ones are checked before the run).
    pub used: BTreeSet<String>,
}

/// `render`'s jobs: each scene file of `files` read ([`clevrtex_dataset::scene_read::read`])
/// with its own passes or `passes`, rendered into `out`; a material unknown to `cat`, or a
/// scene file its metadata would overwrite, refused before anything renders.
pub fn of_scene_files(
    files: Vec<PathBuf>,
    out: &Path,
    passes: Option<Vec<Pass>>,
    cat: &Catalogue,
) -> Result<RunJobs> {
    let mut jobs = Vec::new();
    let mut variants = BTreeSet::new();
    let mut used = BTreeSet::new();
    for f in files {
        let scene = clevrtex_dataset::scene_read::read(&f).map_err(RenderError::Refused)?;
        // Every material known before anything renders (a user one needs `--materials`).
        used.extend(crate::user_materials::used_by_scenes(
            cat,
            [(f.as_path(), &scene)],
        )?);
        // The metadata has the scene file's name: rendering into the folder the scenes came
        // from would replace each scene file with its metadata.
        let meta = layout::sample_dir(out, &scene.variant, scene.index)
            .join(layout::metadata_file(&scene.stem));
        if let (Ok(a), Ok(b)) = (f.canonicalize(), meta.canonicalize()) {
            if a == b {
                return Err(RenderError::Refused(format!(
                    "rendering scene file `{}` would overwrite it with its metadata (same name)\nhint: pass another `--out` than the folder the scenes are in",
                    f.display()
                )));
            }
        }
        let passes = passes.clone().unwrap_or_else(|| scene.passes.clone());
        variants.insert(scene.variant.clone());
        let scene = Arc::new(scene);
        jobs.push(Job {
            index: scene.index,
            variant: scene.variant.clone(),
            stem: scene.stem.clone(),
            passes,
            scene: Arc::new(move |_| Ok((*scene).clone())),
            resample: false,
            source: Some(f.clone()),
        });
    }
    let ledger = match variants.iter().next() {
        Some(v) if variants.len() == 1 => layout::variant_dir(out, v).join("failures.jsonl"),
        _ => out.join("failures.jsonl"),
    };
    Ok(RunJobs {
        jobs: jobs.into(),
        ledger,
        used,
    })
}
