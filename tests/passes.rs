//! The passes `generate` writes: the pass table agrees with the bridge's, every variant
//! renders with only the passes asked for, and camera model, depth and shadow match Blender.

use clevrtex_render::post::{self, decode_png};
use clevrtex_scene::Pass;
use serde_json::Value;

use crate::generate::{files_under, fixture, read_json, render_fixtures};
use crate::util::{blender_or_skip, clevrtex, repo_root, test_blenders, text};

/// The Rust pass table (`clevrtex_scene::passes`) and the bridge's (`blender_scripts/passes.py`)
/// list the same passes, in the same order, with the same EXR layers: read in Blender's own
/// Python, the interpreter that runs the bridge.
#[test]
fn pass_table_rust_and_bridge_agree() {
    let Some(blender) = blender_or_skip("pass_table_rust_and_bridge_agree") else {
        return;
    };
    let scripts = repo_root().join("blender_scripts");
    let expr = format!(
        "import json, sys; sys.path.insert(0, {scripts:?}); import passes; \
         print('@@PASSES@@' + json.dumps([[n, list(p['exr'].items())] for n, p in passes.PASSES.items()]))",
        scripts = scripts.display().to_string()
    );
    // A Python with the `bpy` module (`CLEVRTEX_BLENDER=.venv-bpy/bin/python`) runs the
    // bridge itself, so it reads the table there, without Blender's command line.
    let args: Vec<&str> = match clevrtex_render::blender::flavour(&blender) {
        clevrtex_render::blender::Flavour::PythonModule => vec!["-c", &expr],
        clevrtex_render::blender::Flavour::Executable => vec![
            "-b",
            "--factory-startup",
            "--python-exit-code",
            "1",
            "--python-expr",
            &expr,
        ],
    };
    let out = std::process::Command::new(&blender)
        .args(&args)
        .output()
        .unwrap();
    let stdout = String::from_utf8_lossy(&out.stdout);
    let line = stdout
        .lines()
        .find_map(|l| l.strip_prefix("@@PASSES@@"))
        .unwrap_or_else(|| panic!("no pass table printed: {stdout}\n{}", text(&out)));
    let bridge: Vec<(String, Vec<(String, String)>)> = serde_json::from_str(line).unwrap();
    let rust: Vec<(String, Vec<(String, String)>)> = Pass::ALL
        .iter()
        .map(|p| {
            let layers = p.spec().exr_layers.iter();
            let layers = layers
                .map(|(l, c)| (l.to_string(), c.to_string()))
                .collect();
            (p.name().to_string(), layers)
        })
        .collect();
    assert_eq!(
        bridge, rust,
        "blender_scripts/passes.py PASSES vs clevrtex_scene::passes (names and EXR layers)"
    );
}

#[test]
fn every_variant_renders_and_only_requested_passes_are_written() {
    // On every Blender found: Debian's, and PyPI's bpy when installed.
    for blender in test_blenders("every_variant_renders_and_only_requested_passes_are_written") {
        let dir = tempfile::tempdir().unwrap();
        let scenes = dir.path().join("scenes");
        std::fs::create_dir_all(&scenes).unwrap();
        let variants = ["full", "pbg", "vbg", "grassbg", "camo", "outd", "clevr"];
        for (i, v) in variants.iter().enumerate() {
            let config = clevrtex_scene::Config::builtin(v).unwrap();
            let mut scene = clevrtex_scene::sample(
                &config,
                &clevrtex_scene::SampleRequest {
                    seed: 1,
                    index: i as u64,
                    attempt: 0,
                    total: 10,
                },
            )
            .unwrap();
            scene.render.width = 64;
            scene.render.height = 48;
            scene.render.samples = 1;
            std::fs::write(
                scenes.join(format!("{v}.json")),
                serde_json::to_string(&scene).unwrap(),
            )
            .unwrap();
        }
        let out_dir = dir.path().join("out");
        let out = clevrtex()
            .args([
                "render",
                "--passes",
                "rgb,mask",
                "--workers",
                "1",
                "--blender",
            ])
            .arg(&blender)
            .arg("--out")
            .arg(&out_dir)
            .arg(&scenes)
            .output()
            .unwrap();
        let t = text(&out);
        assert_eq!(out.status.code(), Some(0), "{t}");
        let files = files_under(&out_dir);
        assert_eq!(files.len(), 3 * variants.len(), "{files:?}");
        for (i, v) in variants.iter().enumerate() {
            let stem = format!("clevrtex_{v}/0/CLEVRTEX_{v}_{i:06}");
            for suffix in [".json", ".png", "_flat.png"] {
                assert!(
                    files.contains(&format!("{stem}{suffix}")),
                    "{stem}{suffix}: {files:?}"
                );
            }
            let meta = read_json(&out_dir.join(format!("{stem}.json")));
            assert_eq!(meta["depth_filename"], Value::Null);
            assert_eq!(meta["passes"].as_object().unwrap().len(), 2);
            let mask = decode_png(&out_dir.join(format!("{stem}_flat.png"))).unwrap();
            let n = meta["num_objects"].as_u64().unwrap() as u16;
            assert!(mask.data.iter().all(|&v| v <= n));
            let rgb = decode_png(&out_dir.join(format!("{stem}.png"))).unwrap();
            let spread = rgb.data.iter().max().unwrap() - rgb.data.iter().min().unwrap();
            assert!(spread > 20, "{v}: the image is flat (spread {spread})");
        }
    }
}

#[test]
fn camera_model_depth_and_shadow_match_blender() {
    let Some(blender) = blender_or_skip("camera_model_depth_and_shadow_match_blender") else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let (w, h) = (160, 120);
    let objects = fixture("tiny3", w, h, 4);
    let floor = fixture("empty_floor", 64, 48, 8);
    let stats = render_fixtures(blender, dir.path(), vec![objects.clone(), floor.clone()]);
    assert_eq!(stats.len(), 2);
    let sub = dir.path().join("clevrtex_clevr/0");

    // pixel_coords (Rust camera model) within 0.5 px of Blender's own projection.
    let meta = read_json(&sub.join(format!("{}.json", objects.stem)));
    for (i, blender_xy) in stats[0].projected.iter().enumerate() {
        let rust = &meta["objects"][i]["pixel_coords"];
        let (x, y) = (rust[0].as_f64().unwrap(), rust[1].as_f64().unwrap());
        assert!(
            (x - blender_xy[0]).abs() <= 0.5 && (y - blender_xy[1]).abs() <= 0.5,
            "object {i}: rust ({x}, {y}) vs blender ({}, {})",
            blender_xy[0],
            blender_xy[1]
        );
        assert!((rust[2].as_f64().unwrap() - blender_xy[2]).abs() < 1e-3);
    }

    // Depth of the sphere's nearest point: planar depth of the front surface along the ray
    // through its centre, (|C - O| - r) * cos(angle to the view axis), within 1%.
    let i = objects
        .objects
        .iter()
        .position(|o| o.shape == "sphere")
        .unwrap();
    let sphere = &objects.objects[i];
    let cam = &objects.camera.matrix_world;
    let o = [cam[0][3], cam[1][3], cam[2][3]];
    let fwd = [-cam[0][2], -cam[1][2], -cam[2][2]];
    let d: Vec<f64> = (0..3).map(|k| sphere.location[k] - o[k]).collect();
    let dist = d.iter().map(|v| v * v).sum::<f64>().sqrt();
    let cos = (0..3).map(|k| d[k] / dist * fwd[k]).sum::<f64>();
    let expected = (dist - sphere.scale) * cos;
    let depth = decode_png(&sub.join(format!("{}_depth_0001.png", objects.stem))).unwrap();
    let px = &meta["objects"][i]["pixel_coords"];
    let (x, y) = (
        px[0].as_f64().unwrap() as usize,
        px[1].as_f64().unwrap() as usize,
    );
    let got = depth.data[y * w as usize + x] as f64 * post::DEPTH_SCALE_M;
    assert!(
        (got - expected).abs() / expected < 0.01,
        "sphere depth {got} m vs expected {expected} m"
    );
    assert!(depth.data.contains(&post::DEPTH_BACKGROUND) || depth.data.iter().all(|&v| v < 65535));

    // Objects on a lit floor do cast shadows.
    let shadow = decode_png(&sub.join(format!("{}_shadow_0001.png", objects.stem))).unwrap();
    let shadowed = shadow.data.iter().filter(|&&v| v > 128).count();
    assert!(
        shadowed * 50 > shadow.data.len(),
        "only {shadowed} of {} pixels are shadowed",
        shadow.data.len()
    );

    // Shadow of an empty, lit floor: defined everywhere and ~0.
    let shadow = decode_png(&sub.join(format!("{}_shadow_0001.png", floor.stem))).unwrap();
    let mean = shadow.data.iter().map(|&v| v as f64).sum::<f64>() / shadow.data.len() as f64;
    let dark = shadow.data.iter().filter(|&&v| v > 25).count();
    assert!(mean < 2.0, "mean shadow {mean}/255 on an empty floor");
    assert!(
        dark * 100 < shadow.data.len(),
        "{dark} shadowed pixels on an empty floor"
    );
    // The float passes themselves are finite where it matters.
    let exr =
        clevrtex_render::exr_io::Channels::read(&sub.join(format!("{}_shadow.exr", floor.stem)))
            .unwrap();
    assert!(exr
        .get("ViewLayer.DiffDir.R")
        .unwrap()
        .iter()
        .all(|v| v.is_finite()));
}
