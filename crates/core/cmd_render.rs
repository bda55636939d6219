//! `clevrtex render`: render scene files made by `clevrtex sample`, through the same pool run
//! as `generate` (`run.rs`: [`run_jobs`]; its options [`RunArgs`] in `run_args.rs`).

use std::path::{Path, PathBuf};
use std::sync::Arc;

use anyhow::bail;
use clevrtex_dataset::layout;
use clevrtex_render::pool::Job;
use clevrtex_scene::SceneFile;

use crate::exit::CmdResult;
use crate::run::run_jobs;
use crate::run_args::{parse_passes, RunArgs};

/// Arguments of `clevrtex render`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// Scene files, or folders searched (recursively, as `clevrtex sample --out` lays them
    /// out) for `*.json` scene files.
    #[arg(required = true, value_name = "SCENES")]
    scenes: Vec<PathBuf>,
    #[command(flatten)]
    run: RunArgs,
}

/// Run `clevrtex render`.
pub fn run(args: Args) -> CmdResult {
    let mut files = Vec::new();
    for p in &args.scenes {
        if p.is_dir() {
            let mut found = Vec::new();
            let root = clevrtex_dataset::dataset::root(p)
                .map_err(|e| anyhow::anyhow!("cannot read folder `{}`: {e}", p.display()))?;
            find_scene_files(&root, p, &mut found)?;
            found.sort();
            files.extend(found);
        } else if p.is_file() {
            files.push(p.clone());
        } else if p.exists() {
            bail!(
                "scene path `{}` is neither a file nor a folder (a FIFO or device is not read)\nhint: pass scene files or folders written by `clevrtex sample`",
                p.display()
            );
        } else {
            bail!(
                "scene path `{}` does not exist\nhint: pass scene files or folders written by `clevrtex sample`",
                p.display()
            );
        }
    }
    if files.is_empty() {
        let searched: Vec<String> = args
            .scenes
            .iter()
            .map(|p| format!("`{}`", p.display()))
            .collect();
        bail!(
            "no `*.json` scene files found in {}\nhint: make some with `clevrtex sample --out DIR` and pass that `DIR`",
            searched.join(", ")
        );
    }
    let override_passes = match &args.run.passes {
        Some(list) => Some(parse_passes(list)?),
        None => None,
    };
    let catalogue = args.run.materials.catalogue()?;
    let mut jobs = Vec::new();
    let mut variants = std::collections::BTreeSet::new();
    let mut used = std::collections::BTreeSet::new();
    for f in files {
        let scene = read_scene(&f)?;
        // Every material known before anything renders (a user one needs `--materials`).
        used.extend(clevrtex_render::user_materials::used_by_scenes(
            &catalogue,
            [(f.as_path(), &scene)],
        )?);
        // The metadata has the scene file's name: rendering into the folder the scenes came
        // from would replace each scene file with its metadata.
        let meta = layout::sample_dir(&args.run.out, &scene.variant, scene.index)
            .join(layout::metadata_file(&scene.stem));
        if let (Ok(a), Ok(b)) = (f.canonicalize(), meta.canonicalize()) {
            if a == b {
                bail!(
                    "rendering scene file `{}` would overwrite it with its metadata (same name)\nhint: pass another `--out` than the folder the scenes are in",
                    f.display()
                );
            }
        }
        let passes = override_passes
            .clone()
            .unwrap_or_else(|| scene.passes.clone());
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
        Some(v) if variants.len() == 1 => {
            layout::variant_dir(&args.run.out, v).join("failures.jsonl")
        }
        _ => args.run.out.join("failures.jsonl"),
    };
    run_jobs(&args.run, jobs.into(), ledger, 1, None, (catalogue, used))
}

/// Collect the `*.json` files under `dir` (in the folder given, canonical `root`),
/// recursively (not into linked folders): `clevrtex sample --out DIR` writes them to
/// `DIR/clevrtex_<variant>/<index / 1000>/`, and `clevrtex render DIR` must find them. A file
/// link leading out of the folder given is not followed (the folder is untrusted), and said.
fn find_scene_files(root: &Path, dir: &Path, found: &mut Vec<PathBuf>) -> anyhow::Result<()> {
    let entries = std::fs::read_dir(dir).map_err(|e| {
        anyhow::anyhow!(
            "cannot read folder `{}`: {e}\nhint: pass a readable folder of scene files",
            dir.display()
        )
    })?;
    for entry in entries.flatten() {
        let path = entry.path();
        // Links to folders are not followed: a link back up (`loop -> ..`) would walk the same
        // scenes again without end.
        if entry.file_type().is_ok_and(|t| t.is_dir()) {
            find_scene_files(root, &path, found)?;
        } else if path.extension().is_some_and(|e| e == "json") {
            match clevrtex_dataset::dataset::classify(root, &path) {
                clevrtex_dataset::dataset::Kind::File => found.push(path),
                clevrtex_dataset::dataset::Kind::Skipped(why) => {
                    eprintln!(
                        "warning: scene file `{}` {}",
                        clevrtex_scene::text::printable(&path.display().to_string()),
                        why
                    )
                }
                clevrtex_dataset::dataset::Kind::Dir => {}
            }
        }
    }
    Ok(())
}

/// The largest scene file read: `clevrtex sample` writes a few KB (at most 255 objects); a
/// scene file is not trusted, and its size must not size our memory.
const MAX_SCENE_BYTES: u64 = 4 << 20;

fn read_scene(path: &Path) -> anyhow::Result<SceneFile> {
    let cannot = |e: std::io::Error| {
        anyhow::anyhow!(
            "cannot read scene file `{}`: {e}\nhint: pass scene files written by `clevrtex sample`",
            path.display()
        )
    };
    let mut file = std::fs::File::open(path).map_err(cannot)?;
    let mut bytes = Vec::new();
    std::io::Read::read_to_end(
        &mut std::io::Read::take(&mut file, MAX_SCENE_BYTES + 1),
        &mut bytes,
    )
    .map_err(cannot)?;
    if bytes.len() as u64 > MAX_SCENE_BYTES {
        bail!(
            "scene file `{}` is larger than {} MiB; `clevrtex sample` writes a few KB\nhint: pass scene files written by `clevrtex sample`",
            path.display(),
            MAX_SCENE_BYTES >> 20
        );
    }
    let text = String::from_utf8(bytes).map_err(|e| {
        anyhow::anyhow!(
            "bad scene file `{}`: not UTF-8 text ({e})\nhint: regenerate it with `clevrtex sample`",
            path.display()
        )
    })?;
    let scene: SceneFile = serde_json::from_str(&text).map_err(|e| {
        anyhow::anyhow!(
            "bad scene file `{}`: {e}\nhint: regenerate it with `clevrtex sample`",
            path.display()
        )
    })?;
    if scene.format != clevrtex_scene::scene_file::SCENE_FORMAT
        || scene.version != clevrtex_scene::scene_file::SCENE_VERSION
    {
        bail!(
            "`{}` is not a version {} clevrtex scene file (format `{}`, version {})\nhint: regenerate it with this version's `clevrtex sample`",
            path.display(),
            clevrtex_scene::scene_file::SCENE_VERSION,
            scene.format,
            scene.version
        );
    }
    if let Err(problem) = scene.validate() {
        bail!(
            "bad scene file `{}`: {problem}\nhint: fix that key, or regenerate the file with `clevrtex sample`",
            path.display()
        );
    }
    Ok(scene)
}
