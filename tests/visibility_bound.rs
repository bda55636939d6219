//! The geometric pre-reject and pre-accept of `generate` (`clevrtex_scene::visibility`): its
//! per-object upper bound of visible pixels is never below what Blender's object-index pass
//! counts and its lower bound never above, on real renders of the layouts where the bounds are
//! tightest (the most occluded and cut ones, where the pre-reject fires, and the pre-accepted
//! ones closest to the threshold); the shape tables behind them fit the meshes of every
//! Blender; and a variant whose layouts all fail fails as before.

use clevrtex_render::post::visibility_threshold;
use clevrtex_scene::config::Config;
use clevrtex_scene::visibility::{
    inner_balls, outer_box, visible_pixel_bounds, visible_pixel_lower_bounds,
};
use clevrtex_scene::{sample, Pass, SampleRequest, SceneFile};

use crate::util::{blender_or_skip, clevrtex, repo_root, test_blenders, text};

const W: u32 = 160;
const H: u32 = 120;

/// A `full` layout as the visibility render sees it: undisplaced, one plain material (no
/// material can let a ray through), 1 sample, the object-index pass only.
fn layout(index: u64, attempt: u32) -> SceneFile {
    let c = Config::builtin("full").unwrap();
    let mut s = sample(
        &c,
        &SampleRequest {
            seed: 11,
            index,
            attempt,
            total: 100_000,
        },
    )
    .unwrap();
    s.render.width = W;
    s.render.height = H;
    s.render.samples = 1;
    s.render.adaptive_threshold = None;
    s.passes = vec![Pass::Mask];
    for o in &mut s.objects {
        o.material.name = "plain".into();
        o.material.displacement = None;
    }
    s.backdrop.material.name = "plain".into();
    s.backdrop.material.displacement = None;
    s
}

#[test]
fn the_bound_holds_on_real_renders_of_the_most_occluded_layouts() {
    let Some(blender) =
        blender_or_skip("the_bound_holds_on_real_renders_of_the_most_occluded_layouts")
    else {
        return;
    };
    let threshold = visibility_threshold(W, H);
    // Of 600 layouts, the 12 whose smallest bound is smallest (half pre-rejected at least,
    // where the pre-reject matters), the 8 pre-accepted ones whose smallest lower bound is
    // closest to the threshold, and 4 ordinary ones.
    let mut pool: Vec<(u64, SceneFile, Vec<u64>)> = (0..600)
        .map(|i| {
            let s = layout(i / 3, (i % 3) as u32);
            let b = visible_pixel_bounds(&s).unwrap();
            (*b.iter().min().unwrap(), s, b)
        })
        .collect();
    pool.sort_by_key(|(m, s, _)| (*m, s.index, s.attempt));
    let mut chosen: Vec<(SceneFile, Vec<u64>)> = pool.drain(..12).map(|(_, s, b)| (s, b)).collect();
    let lower_min = |s: &SceneFile| *visible_pixel_lower_bounds(s).unwrap().iter().min().unwrap();
    let mut accepted: Vec<usize> = (0..pool.len())
        .filter(|&k| lower_min(&pool[k].1) > threshold)
        .collect();
    accepted.sort_by_key(|&k| lower_min(&pool[k].1));
    let near: Vec<usize> = accepted.into_iter().take(8).collect();
    chosen.extend(near.iter().map(|&k| (pool[k].1.clone(), pool[k].2.clone())));
    chosen.extend(
        pool.iter()
            .step_by(150)
            .map(|(_, s, b)| (s.clone(), b.clone())),
    );
    let lowers: Vec<Vec<u64>> = chosen
        .iter()
        .map(|(s, _)| visible_pixel_lower_bounds(s).unwrap())
        .collect();
    let preaccepted = lowers
        .iter()
        .filter(|l| l.iter().all(|&px| px > threshold))
        .count();
    assert!(
        preaccepted >= 8,
        "only {preaccepted} pre-accepted layouts chosen"
    );
    let prerejected = chosen
        .iter()
        .filter(|(_, b)| b.iter().any(|&px| px <= threshold))
        .count();
    assert!(
        prerejected >= 6,
        "only {prerejected} pre-rejected layouts chosen"
    );

    let dir = tempfile::tempdir().unwrap();
    let scenes = dir.path().join("scenes");
    std::fs::create_dir(&scenes).unwrap();
    // One file per layout (attempts of one index share a stem: distinct indices instead).
    for (k, (s, _)) in chosen.iter_mut().enumerate() {
        s.index = k as u64;
        s.stem = clevrtex_scene::stem(&s.variant, s.index);
        let text = serde_json::to_string_pretty(s).unwrap();
        std::fs::write(scenes.join(format!("{k}.json")), text).unwrap();
    }
    let data = dir.path().join("data");
    let out = clevrtex()
        .args(["render", "--workers", "1", "--threads", "2", "--blender"])
        .arg(&blender)
        .arg("--out")
        .arg(&data)
        .arg(&scenes)
        .output()
        .unwrap();
    assert!(out.status.success(), "{}", text(&out));
    let mut rejected_by_blender = 0;
    let mut tight = 0;
    for (k, (s, bounds)) in chosen.iter().enumerate() {
        let meta = data
            .join("clevrtex_full/0")
            .join(format!("{}.json", s.stem));
        let meta: serde_json::Value =
            serde_json::from_slice(&std::fs::read(&meta).unwrap()).unwrap();
        let objects = meta["objects"].as_array().unwrap();
        assert_eq!(objects.len(), bounds.len());
        let counts: Vec<u64> = objects
            .iter()
            .map(|o| o["visible_pixels"].as_u64().unwrap())
            .collect();
        for (i, (&px, &bound)) in counts.iter().zip(bounds).enumerate() {
            assert!(
                px >= lowers[k][i],
                "layout {k} (index {}, attempt {}) object {i} ({}): Blender counts {px} pixels, the lower bound says at least {}",
                s.index,
                s.attempt,
                s.objects[i].shape,
                lowers[k][i]
            );
            assert!(
                px <= bound,
                "layout {k} (index {}, attempt {}) object {i} ({}): Blender counts {px} pixels, the bound says at most {bound}",
                s.index,
                s.attempt,
                s.objects[i].shape
            );
            if bound > 0 && px * 2 >= bound {
                tight += 1;
            }
        }
        let pre = bounds.iter().any(|&b| b <= threshold);
        let blender_rejects = counts.iter().any(|&px| px <= threshold);
        if pre {
            // What the pre-reject promises: Blender rejects the layout too.
            assert!(
                blender_rejects,
                "layout {k}: pre-rejected but Blender accepts {counts:?}"
            );
            rejected_by_blender += 1;
        }
        if lowers[k].iter().all(|&px| px > threshold) {
            // What the pre-accept promises: Blender accepts the layout too.
            assert!(
                !blender_rejects,
                "layout {k}: pre-accepted but Blender rejects {counts:?}"
            );
        }
    }
    assert_eq!(rejected_by_blender, prerejected);
    // Not vacuous: most bounds are within 2x of Blender's count.
    let objects: usize = chosen.iter().map(|(_, b)| b.len()).sum();
    assert!(tight * 2 > objects, "{tight} of {objects} bounds within 2x");
}

/// A variant whose objects are all too small to see: every layout is pre-rejected, without a
/// visibility render, and the run fails with the message it always had.
#[test]
fn a_variant_no_layout_of_which_passes_fails_with_the_usual_message() {
    let Some(blender) =
        blender_or_skip("a_variant_no_layout_of_which_passes_fails_with_the_usual_message")
    else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let mut config: serde_json::Value = serde_json::from_str(
        &std::fs::read_to_string(crate::util::repo_root().join("configs/clevr.json")).unwrap(),
    )
    .unwrap();
    config["name"] = "tiny".into();
    for s in config["objects"]["sizes"].as_array_mut().unwrap() {
        s["scale"] = 0.02.into();
    }
    let path = dir.path().join("tiny.json");
    std::fs::write(&path, config.to_string()).unwrap();
    let out = clevrtex()
        .args([
            "generate",
            "--workers",
            "1",
            "-n",
            "1",
            "--width",
            "64",
            "--height",
            "48",
        ])
        .args(["--samples", "1", "--max-attempts", "3", "--blender"])
        .arg(&blender)
        .arg("--config")
        .arg(&path)
        .arg("--out")
        .arg(dir.path().join("out"))
        .output()
        .unwrap();
    let t = text(&out);
    assert_ne!(out.status.code(), Some(0), "{t}");
    assert!(
        t.contains("3 layouts in a row had an object with at most"),
        "not the usual rejects message: {t}"
    );
    // A failed image's rejects are in the run's time split.
    assert!(t.contains("(3 rejected layout(s), "), "{t}");
}

/// The shape tables of the bounds (`inner_balls`, `outer_box`) hold for the meshes every
/// Blender builds: each ball enclosed (no ray leaves it outwards without meeting the mesh), every
/// vertex of the subdivided mesh inside the box and the vertical cylinder
/// (`blender_scripts/dev/inner_balls.py check`).
#[test]
fn the_shape_tables_fit_the_meshes_of_every_blender() {
    let blenders = test_blenders("the_shape_tables_fit_the_meshes_of_every_blender");
    let dir = tempfile::tempdir().unwrap();
    let table: serde_json::Map<String, serde_json::Value> = clevrtex_scene::names::KNOWN_SHAPES
        .iter()
        .map(|&shape| {
            let (b, radial) = outer_box(shape);
            let spec = serde_json::json!({"balls": inner_balls(shape), "box": b, "radial": radial});
            (shape.to_string(), spec)
        })
        .collect();
    let table_path = dir.path().join("table.json");
    std::fs::write(&table_path, serde_json::Value::Object(table).to_string()).unwrap();
    let script = repo_root().join("blender_scripts/dev/inner_balls.py");
    for (k, blender) in blenders.iter().enumerate() {
        let report = dir.path().join(format!("report-{k}.json"));
        let args = [
            "check".into(),
            table_path.clone().into_os_string(),
            report.clone().into_os_string(),
        ];
        let flavour = clevrtex_render::blender::flavour(blender);
        let out = clevrtex_render::blender::worker_command(blender, flavour, &script, &args)
            .output()
            .unwrap();
        let report = std::fs::read_to_string(&report).unwrap_or_default();
        assert!(
            out.status.success(),
            "{}: the shape tables do not fit: {report}\n{}",
            blender.display(),
            text(&out)
        );
        let parsed: serde_json::Value = serde_json::from_str(&report).unwrap();
        assert_eq!(parsed.as_object().unwrap().len(), 8, "{report}");
    }
}
