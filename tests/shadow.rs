//! The shadow pass on a textured, displaced floor (real Blender).

use clevrtex_render::post::decode_png;
use clevrtex_scene::SceneFile;

use crate::generate::{fixture, render_fixtures};
use crate::util::blender_or_skip;

/// The shadow pass on a textured, displaced floor (`full8.json`'s cobblestones), tiny and
/// few samples: with no object the pass is <= 0.02 everywhere (the pass up to 0.9, an
/// 8-sample no-shadow render against the final render, reached ~0.6 on such a floor), and
/// with one cube the cube's shadow is there while most of the floor stays exactly 0 (the
/// light with and without object shadows comes from the same samples of one render, so only
/// blocked shadow rays differ); a floor whose material an object shares stays as open (the
/// objects' transparency to shadow rays goes by object, not by material; checked to fail
/// when it went by material).
#[test]
fn shadow_pass_is_zero_on_an_open_floor_and_dark_beside_a_cube() {
    let Some(blender) =
        blender_or_skip("shadow_pass_is_zero_on_an_open_floor_and_dark_beside_a_cube")
    else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let with_index = |mut s: SceneFile, index: u64, objects: usize| {
        s.index = index;
        s.stem = format!("CLEVRTEX_full_{index:06}");
        s.objects.truncate(objects);
        s
    };
    let floor = with_index(fixture("full8", 64, 48, 32), 100, 0);
    let cube = with_index(fixture("full8", 64, 48, 32), 101, 1);
    assert_eq!(cube.objects[0].shape, "cube");
    // The same cube with one shadow sample per render (`render.shadow_samples`).
    let mut one = with_index(fixture("full8", 64, 48, 32), 102, 1);
    one.render.shadow_samples = Some(1);
    // An object that shares the backdrop's material (as in `camo`), far below the floor where
    // it blocks no light: the shadow render makes objects transparent to shadow rays through
    // their materials, and the backdrop must stay opaque (its relief shadows itself in both
    // channels), so the floor is as open as without the object.
    let mut shared = with_index(fixture("full8", 64, 48, 32), 103, 1);
    shared.objects[0].material = shared.backdrop.material.clone();
    shared.objects[0].location = [0.0, 0.0, -50.0];
    let stats = render_fixtures(
        blender,
        dir.path(),
        vec![floor.clone(), cube.clone(), one.clone(), shared.clone()],
    );
    assert!(stats[0].render_s > 0.0 && stats[1].render_s > 0.0);
    // The bridge's phases (docs/bridge-protocol.md): the displaced floor's material, its
    // displacement and its path tracing are each reported.
    let p = &stats[0].phases;
    assert!(p.materials.cpu_s > 0.0, "{p:?}");
    assert!(p.displacement.cpu_s > 0.0, "{p:?}");
    assert!(p.path_tracing.cpu_s > 0.0 && p.write.wall_s > 0.0, "{p:?}");
    let sub = dir.path().join("clevrtex_full/0");
    let shadow = |stem: &str| decode_png(&sub.join(format!("{stem}_shadow_0001.png"))).unwrap();

    let open = shadow(&floor.stem);
    let max = open.data.iter().copied().max().unwrap();
    assert!(
        f64::from(max) / 255.0 <= 0.02,
        "open floor: shadow up to {max}/255"
    );
    assert!(sub.join(format!("{}_shadow.exr", floor.stem)).is_file());
    let max = shadow(&shared.stem).data.iter().copied().max().unwrap();
    assert!(
        f64::from(max) / 255.0 <= 0.02,
        "open floor sharing its material with an object: shadow up to {max}/255"
    );

    let ids = decode_png(&sub.join(format!("{}_flat.png", cube.stem))).unwrap();
    let s = shadow(&cube.stem);
    let on_floor: Vec<u16> = (0..s.data.len())
        .filter(|&i| ids.data[i] == 0)
        .map(|i| s.data[i])
        .collect();
    // Its shadow is soft (four big lights; measured here with 8 shadow samples
    // of a 32-sample render: up to 0.93, 2.4% of the floor >= 0.2).
    let darkest = on_floor.iter().copied().max().unwrap();
    let dark = on_floor.iter().filter(|&&v| v >= 51).count();
    let zero = on_floor.iter().filter(|&&v| v == 0).count();
    assert!(
        darkest >= 102,
        "the cube's shadow reaches only {darkest}/255"
    );
    assert!(
        dark * 100 >= on_floor.len(),
        "only {dark} of {} floor pixels beside the cube have shadow >= 0.2",
        on_floor.len()
    );
    assert!(
        zero * 2 >= on_floor.len(),
        "only {zero} of {} floor pixels are exactly unshadowed",
        on_floor.len()
    );
    // The soft shadow has values between fully lit and fully shadowed, which one sample
    // (`render.shadow_samples` = 1 reaching the bridge) cannot have: each pixel's one light
    // sample is blocked by an object (green 0, red kept: 255) or not (green = red: 0).
    let between = s.data.iter().filter(|&&v| v > 0 && v < 255).count();
    assert!(between > 0, "the default samples give no partial shadow");
    let single = shadow(&one.stem);
    let partial = single.data.iter().filter(|&&v| v > 0 && v < 255).count();
    assert_eq!(
        partial, 0,
        "partial shadow values with one sample ({between} with the default)"
    );
    assert!(single.data.contains(&255), "one sample: no shadow at all");
}

/// Material templates (`shading.assign_materials`): a scene rendered by a worker whose
/// templates were built for other instances of the same materials (other random values,
/// other strengths) gives the same mask, depth, albedo and shadow bytes (the normal within
/// its own run-to-run noise) as in a fresh worker, which builds every tree for the scene's
/// own instances; checked to fail when a template copy kept the first instance's values.
#[test]
fn material_templates_render_as_trees_built_per_instance() {
    let Some(blender) = blender_or_skip("material_templates_render_as_trees_built_per_instance")
    else {
        return;
    };
    let scene = |index: u64, random: f64| {
        let mut s = fixture("full8", 48, 36, 2);
        s.index = index;
        s.stem = format!("CLEVRTEX_full_{index:06}");
        s.objects.truncate(3);
        if random > 0.0 {
            s.backdrop.material.random = random;
            if let Some(d) = s.backdrop.material.displacement.as_mut() {
                *d *= 0.5;
            }
            for o in &mut s.objects {
                o.material.random = (o.material.random + random) % 1.0;
            }
        }
        s
    };
    let fresh = tempfile::tempdir().unwrap();
    render_fixtures(blender.clone(), fresh.path(), vec![scene(7, 0.0)]);
    let reused = tempfile::tempdir().unwrap();
    render_fixtures(blender, reused.path(), vec![scene(6, 0.61), scene(7, 0.0)]);
    let read = |dir: &std::path::Path, pass: &str| {
        decode_png(&dir.join(format!("clevrtex_full/0/CLEVRTEX_full_000007{pass}"))).unwrap()
    };
    for pass in [
        "_flat.png",
        "_depth_0001.png",
        "_albedo_0001.png",
        "_shadow_0001.png",
    ] {
        let (a, b) = (read(fresh.path(), pass), read(reused.path(), pass));
        assert!(a.data == b.data, "{pass} differs");
    }
    // The 16-bit normal pass is not bit-reproducible even between two runs of one build (a
    // few pixels by a few units of 65535: two `generate` runs of main, --threads 1): within 8.
    let (a, b) = (
        read(fresh.path(), "_normal_0001.png"),
        read(reused.path(), "_normal_0001.png"),
    );
    let worst = a
        .data
        .iter()
        .zip(&b.data)
        .map(|(x, y)| x.abs_diff(*y))
        .max()
        .unwrap();
    assert!(worst <= 8, "normal differs by {worst}/65535");
}
