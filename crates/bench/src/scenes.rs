//! The bench's scenes: fixed variants and seeds, so every machine benchmarks the same images.

use std::time::Duration;

use clevrtex_scene::quality::Sampling;
use clevrtex_scene::{Config, Pass, SampleRequest, SceneFile};

/// Variants of the bench scenes, cycled.
pub const VARIANTS: [&str; 8] = [
    "full", "camo", "pbg", "vbg", "grassbg", "outd", "clevr", "full",
];
/// Seed of the bench scenes: fixed, so every machine benchmarks the same images.
pub const SEED: u64 = 2024;
/// Cycles seed of the references (the rungs use the default, 0).
pub const REFERENCE_SEED: u32 = 1;

/// One scene of the bench.
pub struct BenchScene {
    /// `<variant>#<i>`, e.g. `camo#1`.
    pub label: String,
    /// The scene file, with the rungs' passes (RGB, mask, depth).
    pub scene: SceneFile,
}

/// The first `n` bench scenes at `width` x `height`.
pub fn bench_scenes(n: usize, width: u32, height: u32) -> anyhow::Result<Vec<BenchScene>> {
    bench_scenes_in(n, width, height, None)
}

/// [`bench_scenes`], the textured materials drawn from the `user` set of `user` when given
/// (`bench render --materials DIR`: [`Config::use_material_set`]); the layouts are the same.
pub fn bench_scenes_in(
    n: usize,
    width: u32,
    height: u32,
    user: Option<&clevrtex_materials::Catalogue>,
) -> anyhow::Result<Vec<BenchScene>> {
    (0..n)
        .map(|i| {
            let variant = VARIANTS[i % VARIANTS.len()];
            let mut config = match user {
                Some(cat) => {
                    let mut c = Config::builtin_in(variant, cat)?;
                    c.use_material_set(cat, clevrtex_materials::Set::User)?;
                    c
                }
                None => Config::builtin(variant)?,
            };
            config.base.render.width = width;
            config.base.render.height = height;
            config.base.passes = vec![Pass::Rgb, Pass::Mask, Pass::Depth];
            let req = SampleRequest {
                seed: SEED,
                index: i as u64,
                attempt: 0,
                total: 1000.max(n as u64),
            };
            let scene = clevrtex_scene::sample(&config, &req)?;
            Ok(BenchScene {
                label: format!("{variant}#{i}"),
                scene,
            })
        })
        .collect()
}

/// The scene files `files` (from `clevrtex sample`, found by
/// `clevrtex_dataset::scene_read::collect`) as bench scenes at `width` x `height` with the
/// rungs' passes: `bench render --scene`, e.g. the scenes of a variant with the most relief.
/// Each file is read capped and validated (it is not trusted), its materials must be in
/// `cat` (a user one needs `--materials`), and each is labelled by its stem, which must be
/// unique (the stem names the scene's rows in the CSV).
pub fn file_scenes(
    files: &[std::path::PathBuf],
    width: u32,
    height: u32,
    cat: &clevrtex_materials::Catalogue,
) -> anyhow::Result<Vec<BenchScene>> {
    let mut labels = std::collections::BTreeMap::new();
    files
        .iter()
        .map(|f| {
            let mut scene = clevrtex_dataset::scene_read::read(f).map_err(anyhow::Error::msg)?;
            clevrtex_render::user_materials::used_by_scenes(cat, [(f.as_path(), &scene)])?;
            let label = clevrtex_scene::text::printable(&scene.stem).into_owned();
            if let Some(first) = labels.insert(label.clone(), f) {
                anyhow::bail!(
                    "scene files `{}` and `{}` are both `{label}`: the bench names a scene's rows by its stem\nhint: pass scene files of one `clevrtex sample` run, or copy one under another name",
                    first.display(),
                    f.display()
                );
            }
            scene.render.width = width;
            scene.render.height = height;
            scene.passes = vec![Pass::Rgb, Pass::Mask, Pass::Depth];
            Ok(BenchScene { label, scene })
        })
        .collect()
}

/// `scene` with the sampling settings `s`.
pub fn with_sampling(scene: &SceneFile, s: &Sampling) -> SceneFile {
    let mut scene = scene.clone();
    s.apply(&mut scene.render);
    scene
}

/// Per-request time limit: generous (the machine may be shared), scaled with the work.
pub fn timeout_for(scene: &SceneFile) -> Duration {
    let r = &scene.render;
    let work = f64::from(r.samples) * f64::from(r.width) * f64::from(r.height);
    Duration::from_secs_f64(300.0 + work * 4e-5)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn bench_scenes_are_fixed_and_cover_variants() {
        let a = bench_scenes(3, 64, 48).unwrap();
        let b = bench_scenes(3, 64, 48).unwrap();
        assert_eq!(a.len(), 3);
        for (x, y) in a.iter().zip(&b) {
            assert_eq!(x.scene, y.scene);
            assert_eq!((x.scene.render.width, x.scene.render.height), (64, 48));
            assert_eq!(x.scene.passes, vec![Pass::Rgb, Pass::Mask, Pass::Depth]);
        }
        assert_eq!(
            a.iter().map(|s| s.label.as_str()).collect::<Vec<_>>(),
            ["full#0", "camo#1", "pbg#2"]
        );
    }
}
