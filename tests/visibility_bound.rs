//! The geometric pre-reject of `generate` (`clevrtex_scene::visibility`): its per-object bound
//! of visible pixels is never below what Blender's object-index pass counts, on real renders
//! of the layouts where the bound is tightest (the most occluded and cut ones, where the
//! pre-reject fires), and a variant whose layouts all fail fails as before.

use clevrtex_render::post::visibility_threshold;
use clevrtex_scene::config::Config;
use clevrtex_scene::visibility::visible_pixel_bounds;
use clevrtex_scene::{sample, Pass, SampleRequest, SceneFile};

use crate::util::{blender_or_skip, clevrtex, text};

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
    // where the pre-reject matters) and 4 ordinary ones.
    let mut pool: Vec<(u64, SceneFile, Vec<u64>)> = (0..600)
        .map(|i| {
            let s = layout(i / 3, (i % 3) as u32);
            let b = visible_pixel_bounds(&s).unwrap();
            (*b.iter().min().unwrap(), s, b)
        })
        .collect();
    pool.sort_by_key(|(m, s, _)| (*m, s.index, s.attempt));
    let mut chosen: Vec<(SceneFile, Vec<u64>)> = pool.drain(..12).map(|(_, s, b)| (s, b)).collect();
    chosen.extend(pool.into_iter().step_by(150).map(|(_, s, b)| (s, b)));
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
