//! PBR texture folders (Poly Haven, ambientCG) as user materials of `--materials DIR`: what
//! is read, what is refused before any render, and real renders on Blender 3.4 and bpy 4.5
//! whose albedo pass shows the maps' colour. Folders are built by `util::pbr_folder`.

use std::path::Path;
use std::sync::atomic::AtomicBool;
use std::sync::Arc;
use std::time::Duration;

use clevrtex_render::{
    BridgeDir, MaterialMode, MaterialSettings, Mode, Session, Worker, WorkerOptions,
};
use serde_json::Value;

use crate::util::{pbr_folder, pbr_map, run, test_blenders, text, PbrLayout};

/// `clevrtex materials json --materials dir`, parsed (asserting success).
fn resolved(dir: &Path) -> Value {
    let out = run(&["materials", "json", "--materials", dir.to_str().unwrap()]);
    assert!(out.status.success(), "{}", text(&out));
    serde_json::from_slice(&out.stdout).unwrap()
}

fn file_name(v: &Value) -> &str {
    v.as_str()
        .and_then(|p| Path::new(p).file_name())
        .and_then(|n| n.to_str())
        .unwrap_or_else(|| panic!("not a path: {v}"))
}

#[test]
fn pbr_folders_of_both_layouts_resolve_to_their_maps() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    pbr_folder(d, "Brick PH", PbrLayout::PolyHaven, [200, 40, 30]);
    pbr_folder(d, "rock", PbrLayout::AmbientCg, [30, 60, 200]);
    // Several resolutions and formats: the largest nominal resolution within the cap (2k;
    // 16k, which Poly Haven ships, is over the 8192-pixel cap), PNG before JPEG, an OpenGL
    // normal map before a DirectX one.
    let multi = d.join("multi");
    std::fs::create_dir(&multi).unwrap();
    for (name, value) in [
        ("m_diff_1k.jpg", &[10u8, 20, 30][..]),
        ("m_diff_2k.jpg", &[10, 20, 30]),
        ("m_diff_2k.png", &[10, 20, 30]),
        ("m_diff_16k.jpg", &[10, 20, 30]),
        ("m_nor_dx_2k.png", &[128, 128, 255]),
        ("m_nor_gl_2k.png", &[128, 128, 255]),
        ("m_rough_1k.jpg", &[100]),
    ] {
        pbr_map(&multi.join(name), 16, 16, value);
    }
    // A `.blend` pack's texture folder (ClevrTex `_COL_` names) is not a PBR folder.
    let textures = d.join("textures");
    std::fs::create_dir(&textures).unwrap();
    pbr_map(&textures.join("Bricks_COL_3K.jpg"), 8, 8, &[1, 2, 3]);

    let list = run(&["materials", "list", "--materials", d.to_str().unwrap()]);
    assert!(list.status.success(), "{}", text(&list));
    let listed = String::from_utf8_lossy(&list.stdout);
    for name in ["brick_ph", "rock", "multi"] {
        assert!(
            listed
                .lines()
                .any(|l| l.starts_with(&format!("{name} ")) && l.contains(" user ")),
            "{name} not listed:\n{listed}"
        );
    }
    assert!(
        !listed.lines().any(|l| l.starts_with("textures ")),
        "{listed}"
    );

    let v = resolved(d);
    let m = &v["materials"];
    let ph = &m["brick_ph"];
    assert_eq!(ph["kind"], "pbr");
    assert_eq!(ph["layout"], "polyhaven");
    assert_eq!(ph["normal_convention"], "gl");
    assert_eq!(ph["displaces"], true);
    assert_eq!(ph["tile"], 1.0);
    assert_eq!(file_name(&ph["maps"]["color"]), "test_slug_diff_1k.jpg");
    assert_eq!(file_name(&ph["maps"]["arm"]), "test_slug_arm_1k.jpg");
    assert_eq!(
        file_name(&ph["maps"]["displacement"]),
        "test_slug_disp_1k.png"
    );
    let acg = &m["rock"];
    assert_eq!(acg["layout"], "ambientcg");
    assert_eq!(acg["normal_convention"], "dx");
    assert_eq!(
        file_name(&acg["maps"]["roughness"]),
        "Test001_1K-JPG_Roughness.jpg"
    );
    assert!(acg["maps"].get("arm").is_none(), "{acg}");
    let multi = &m["multi"];
    assert_eq!(multi["resolution"], 2048);
    assert_eq!(file_name(&multi["maps"]["color"]), "m_diff_2k.png");
    assert_eq!(file_name(&multi["maps"]["normal"]), "m_nor_gl_2k.png");
    assert_eq!(multi["normal_convention"], "gl");
    // Maps of another resolution than the colour map's are not mixed in.
    assert!(multi["maps"].get("roughness").is_none(), "{multi}");
    assert_eq!(multi["displaces"], false);

    // `material.json` sets the world scale and the relief.
    std::fs::write(
        d.join("rock/material.json"),
        r#"{"tile": 0.25, "relief": 0.1, "description": "grey rock"}"#,
    )
    .unwrap();
    let acg = &resolved(d)["materials"]["rock"];
    assert_eq!(
        (acg["tile"].as_f64(), acg["relief"].as_f64()),
        (Some(0.25), Some(0.1))
    );
    assert_eq!(acg["description"], "grey rock");
}

/// One bad PBR folder: `materials list --materials DIR` exits 1 before any render, the
/// message naming the material and the file (`names`) and giving a hint.
fn refused(setup: impl FnOnce(&Path), names: &[&str], problem: &str) {
    let dir = tempfile::tempdir().unwrap();
    let mats = dir.path().join("mats");
    std::fs::create_dir(&mats).unwrap();
    setup(&mats);
    let out = run(&["materials", "list", "--materials", mats.to_str().unwrap()]);
    let t = text(&out);
    assert_eq!(out.status.code(), Some(1), "{problem}: {t}");
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(stderr.contains(problem), "{problem}: {t}");
    for n in names {
        assert!(stderr.contains(n), "{problem}: `{n}` not named: {t}");
    }
    assert!(stderr.contains("\nhint: "), "{t}");
}

#[test]
fn bad_pbr_folders_are_refused_by_name_before_rendering() {
    let ph = |d: &Path| d.join("wall");
    let mk = |d: &Path| std::fs::create_dir(ph(d)).unwrap();
    refused(
        |d| {
            mk(d);
            pbr_map(&ph(d).join("w_nor_gl_1k.png"), 8, 8, &[128, 128, 255]);
        },
        &["`wall`", "mats/wall"],
        "has no colour map",
    );
    refused(
        |d| {
            mk(d);
            pbr_map(&ph(d).join("w_diff_1k.png"), 8, 8, &[90]);
        },
        &["`wall`", "w_diff_1k.png"],
        "colour map of material `wall` has 1 channel(s)",
    );
    refused(
        |d| {
            pbr_folder(d, "wall", PbrLayout::AmbientCg, [1, 2, 3]);
            pbr_map(&ph(d).join("Test001_1K-JPG_NormalGL.jpg"), 8, 8, &[128]);
        },
        &["`wall`", "Test001_1K-JPG_NormalGL.jpg"],
        "normal map of material `wall` has 1 channel(s)",
    );
    // A corrupt JPEG (a JPEG start, then garbage) and a text file named as a map.
    for (file, bytes) in [
        (
            "w_diff_1k.jpg",
            &b"\xff\xd8\xff\xe0garbage, not a jpeg at all"[..],
        ),
        ("w_rough_1k.png", &b"hello"[..]),
    ] {
        refused(
            |d| {
                mk(d);
                pbr_map(&ph(d).join("w_diff_1k.png"), 8, 8, &[9, 9, 9]);
                std::fs::write(ph(d).join(file), bytes).unwrap();
                if file.ends_with(".jpg") {
                    std::fs::remove_file(ph(d).join("w_diff_1k.png")).unwrap();
                }
            },
            &["`wall`", file],
            "is not a readable image",
        );
    }
    // Over the cap on a loaded texture (`texture::MAX_TEXTURE_SIDE`, shared with the
    // `.blend` textures): an 8,193 x 1 map is a few bytes on disk.
    refused(
        |d| {
            mk(d);
            pbr_map(&ph(d).join("w_diff_1k.png"), 8_193, 1, &[9, 9, 9]);
        },
        &["`wall`", "w_diff_1k.png", "8193x1 pixels"],
        "a side may be 1 to 8192",
    );
    // A map, and a whole folder, linked out of the material directory.
    refused(
        |d| {
            mk(d);
            let outside = d.parent().unwrap().join("outside.png");
            pbr_map(&outside, 8, 8, &[9, 9, 9]);
            std::os::unix::fs::symlink(&outside, ph(d).join("w_diff_1k.png")).unwrap();
        },
        &["`wall`", "w_diff_1k.png"],
        "is a link out of the material directory",
    );
    refused(
        |d| {
            let outside = pbr_folder(
                d.parent().unwrap(),
                "elsewhere",
                PbrLayout::PolyHaven,
                [1, 2, 3],
            );
            std::os::unix::fs::symlink(outside, ph(d)).unwrap();
        },
        &["`wall`", "mats/wall"],
        "is a link out of the material directory",
    );
    // A FIFO named as a map is refused without being opened (which would block).
    refused(
        |d| {
            mk(d);
            let fifo = ph(d).join("w_diff_1k.jpg");
            let made = std::process::Command::new("mkfifo").arg(&fifo).status();
            assert!(made.is_ok_and(|s| s.success()), "mkfifo");
        },
        &["`wall`", "w_diff_1k.jpg"],
        "is not a regular file",
    );
    // A name taken by a built-in, two materials' maps in one folder, bad settings.
    refused(
        |d| {
            pbr_folder(d, "Bricks", PbrLayout::PolyHaven, [1, 2, 3]);
        },
        &["`bricks`", "mats/Bricks"],
        "is already defined by",
    );
    refused(
        |d| {
            pbr_folder(d, "wall", PbrLayout::PolyHaven, [1, 2, 3]);
            pbr_map(&ph(d).join("other_diff_1k.jpg"), 8, 8, &[9, 9, 9]);
        },
        &["`wall`", "`other`", "`test_slug`"],
        "holds maps of more than one material",
    );
    refused(
        |d| {
            pbr_folder(d, "wall", PbrLayout::PolyHaven, [1, 2, 3]);
            std::fs::write(ph(d).join("material.json"), r#"{"tile": -1}"#).unwrap();
        },
        &["wall/material.json", "`tile`"],
        "bad value `-1`",
    );
}

/// The catalogue of `--materials dir` rendered by a worker of `blender`: a `full` scene whose
/// objects are all the Poly Haven folder's material (red) and whose backdrop is the ambientCG
/// folder's (blue, displaced: `full` backdrops have displacement 0.35). The albedo pass is
/// the maps' colour: linear sRGB of the colour map, everywhere, on both.
#[test]
fn pbr_folders_render_with_their_colour_in_the_albedo_pass() {
    let blenders = test_blenders("pbr_folders_render_with_their_colour_in_the_albedo_pass");
    if blenders.is_empty() {
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let mats = dir.path().join("mats");
    let (red, blue) = ([200u8, 40, 30], [30u8, 60, 200]);
    pbr_folder(&mats, "objects_ph", PbrLayout::PolyHaven, red);
    let acg = pbr_folder(&mats, "backdrop_acg", PbrLayout::AmbientCg, blue);
    // The backdrop's colour map is a 16-bit PNG (ambientCG's PNG downloads), which Blender
    // loads as floats: still sRGB. PNG is preferred to the JPEG of the same resolution.
    let wide = image::ImageBuffer::<image::Rgb<u16>, _>::from_pixel(
        32,
        32,
        image::Rgb(blue.map(|c| u16::from(c) * 257)),
    );
    wide.save(acg.join("Test001_1K-PNG_Color.png")).unwrap();
    let catalogue = run(&["materials", "json", "--materials", mats.to_str().unwrap()]);
    assert!(catalogue.status.success(), "{}", text(&catalogue));
    let bridge = BridgeDir::create(&String::from_utf8(catalogue.stdout).unwrap()).unwrap();

    let scenes = dir.path().join("scenes");
    let s = run(&[
        "sample",
        "--variant",
        "full",
        "-n",
        "1",
        "--seed",
        "5",
        "--out",
        scenes.to_str().unwrap(),
    ]);
    assert!(s.status.success(), "{}", text(&s));
    let scene_path = scenes.join("clevrtex_full/0/CLEVRTEX_full_000000.json");
    let mut scene: Value = serde_json::from_slice(&std::fs::read(&scene_path).unwrap()).unwrap();
    scene["render"]["width"] = 64.into();
    scene["render"]["height"] = 48.into();
    scene["render"]["samples"] = 4.into();
    scene["passes"] = serde_json::json!(["rgb", "mask", "albedo"]);
    for o in scene["objects"].as_array_mut().unwrap() {
        o["material"]["name"] = "objects_ph".into();
    }
    scene["backdrop"]["material"]["name"] = "backdrop_acg".into();
    assert!(scene["backdrop"]["material"]["displacement"].as_f64() > Some(0.0));
    std::fs::write(&scene_path, serde_json::to_vec(&scene).unwrap()).unwrap();

    let lin = |c: [u8; 3]| c.map(|x| clevrtex_materials::srgb_to_linear(x) as f32);
    let (red, blue) = (lin(red), lin(blue));
    for blender in blenders {
        let out = dir
            .path()
            .join(format!("out-{}", blender.display()).replace('/', "_"));
        std::fs::create_dir(&out).unwrap();
        let opts = WorkerOptions::new(blender.clone(), &bridge, Arc::new(AtomicBool::new(false)))
            .with_threads(1);
        let mut worker = Worker::start(&opts).unwrap();
        let reply = worker
            .render(&scene_path, Mode::Final, &out, Duration::from_secs(600))
            .unwrap_or_else(|e| panic!("{}: {e}", blender.display()));
        worker.quit();
        let passes = reply.files.get("passes").expect("a passes file");
        let ch = clevrtex_render::exr_io::Channels::read(passes).unwrap();
        let names: Vec<&String> = ch.channels.keys().collect();
        let get = |c: &str| {
            let key = names
                .iter()
                .find(|k| k.contains("BaseCol") && k.ends_with(&format!(".{c}")))
                .unwrap_or_else(|| panic!("no albedo channel {c} in {names:?}"));
            ch.get(key).unwrap()
        };
        let (r, g, b) = (get("R"), get("G"), get("B"));
        let near = |i: usize, c: [f32; 3]| {
            (r[i] - c[0]).abs() < 0.03 && (g[i] - c[1]).abs() < 0.03 && (b[i] - c[2]).abs() < 0.03
        };
        let n = r.len();
        let on_objects = (0..n).filter(|&i| near(i, red)).count();
        let on_backdrop = (0..n).filter(|&i| near(i, blue)).count();
        let shown = format!(
            "{}: {on_objects} red, {on_backdrop} blue of {n} pixels (pixel 0: {} {} {})",
            blender.display(),
            r[0],
            g[0],
            b[0]
        );
        eprintln!("{shown}");
        // Antialiased object edges mix the two; every other pixel is one of them.
        assert!(on_objects + on_backdrop >= n * 85 / 100, "{shown}");
        assert!(on_objects >= n / 50 && on_backdrop >= n / 4, "{shown}");
    }
}

/// A tangent-space normal (x, y, z) as an 8-bit normal-map pixel.
fn encoded(n: [f64; 3]) -> [u8; 3] {
    n.map(|c| ((c * 0.5 + 0.5) * 255.0).round() as u8)
}

/// The normal-map conventions: an OpenGL map tilting the normals towards +v and a DirectX
/// map of the same surface (green flipped) render alike; the DirectX map read as OpenGL (the
/// flip forgotten) and a flat map do not; and the tilts point the right way (towards the
/// light is brighter). Renders of a lit sphere (`materials cost` scene).
#[test]
fn directx_normal_maps_render_as_their_opengl_twins() {
    let blenders = test_blenders("directx_normal_maps_render_as_their_opengl_twins");
    if blenders.is_empty() {
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let mats = dir.path().join("mats");
    let grey = [128, 128, 128];
    let up = encoded([0.0, 0.6, 0.8]);
    let down = encoded([0.0, -0.6, 0.8]);
    let flat = encoded([0.0, 0.0, 1.0]);
    let gl = pbr_folder(&mats, "gl_up", PbrLayout::PolyHaven, grey);
    pbr_map(&gl.join("test_slug_nor_gl_1k.png"), 32, 32, &up);
    let dx = pbr_folder(&mats, "dx_up", PbrLayout::AmbientCg, grey);
    pbr_map(&dx.join("Test001_1K-JPG_NormalDX.jpg"), 32, 32, &down);
    let wrong = pbr_folder(&mats, "dx_as_gl", PbrLayout::AmbientCg, grey);
    pbr_map(&wrong.join("Test001_1K-JPG_NormalDX.jpg"), 32, 32, &up);
    let fl = pbr_folder(&mats, "flat", PbrLayout::PolyHaven, grey);
    pbr_map(&fl.join("test_slug_nor_gl_1k.png"), 32, 32, &flat);
    // Tilted towards +u and -u: the key light is on the +x side, where u runs on the faces
    // the camera sees (the sphere's front, projected along y: u = x, v = z).
    for (name, n) in [("right", [0.6, 0.0, 0.8]), ("left", [-0.6, 0.0, 0.8])] {
        let f = pbr_folder(&mats, name, PbrLayout::PolyHaven, grey);
        pbr_map(&f.join("test_slug_nor_gl_1k.png"), 32, 32, &encoded(n));
    }
    let catalogue = run(&["materials", "json", "--materials", mats.to_str().unwrap()]);
    assert!(catalogue.status.success(), "{}", text(&catalogue));
    let bridge = BridgeDir::create(&String::from_utf8(catalogue.stdout).unwrap()).unwrap();
    let settings = MaterialSettings {
        mode: MaterialMode::Cost,
        size: 96,
        samples: 16,
        displacement: 0.0,
        random: 0.37,
    };
    for blender in blenders {
        let out = dir
            .path()
            .join(format!("out-{}", blender.display()).replace('/', "_"));
        std::fs::create_dir(&out).unwrap();
        let mut session = Session::new(
            WorkerOptions::new(blender.clone(), &bridge, Arc::new(AtomicBool::new(false))),
            0,
            None,
        );
        let mut px = std::collections::BTreeMap::new();
        for name in ["gl_up", "dx_up", "dx_as_gl", "flat", "right", "left"] {
            let reply = session
                .request(&mut (), |w| {
                    w.material(&settings, name, &out, Duration::from_secs(600))
                })
                .unwrap_or_else(|e| panic!("{name}: {e}"));
            px.insert(name, image::open(&reply.file).unwrap().to_rgb8().into_raw());
        }
        session.close();
        let diff = |a: &str, b: &str| {
            let (a, b) = (&px[a], &px[b]);
            let sum: f64 = a
                .iter()
                .zip(b)
                .map(|(x, y)| f64::from(x.abs_diff(*y)))
                .sum();
            sum / a.len() as f64
        };
        let shown = format!(
            "{}: mean |difference| gl_up vs dx_up {:.2}, vs dx_as_gl {:.2}, vs flat {:.2}",
            blender.display(),
            diff("gl_up", "dx_up"),
            diff("gl_up", "dx_as_gl"),
            diff("gl_up", "flat")
        );
        eprintln!("{shown}");
        let mean = |a: &str| px[a].iter().map(|&x| f64::from(x)).sum::<f64>() / px[a].len() as f64;
        let means = format!(
            "mean level: up {:.1}, down (dx_as_gl) {:.1}, right {:.1}, left {:.1}",
            mean("gl_up"),
            mean("dx_as_gl"),
            mean("right"),
            mean("left")
        );
        eprintln!("{means}");
        // The lights are above and to the right: normals turned towards +v (up) and +u
        // (right) catch more of them than their mirror images.
        assert!(mean("gl_up") > mean("dx_as_gl") + 2.0, "{means}");
        assert!(mean("right") > mean("left") + 2.0, "{means}");
        let twins = diff("gl_up", "dx_up");
        assert!(twins < 1.5, "{shown}");
        assert!(diff("gl_up", "dx_as_gl") > 4.0 * twins.max(0.5), "{shown}");
        assert!(diff("gl_up", "flat") > 2.0 * twins.max(0.5), "{shown}");
    }
}

/// The maps' world scale is a property of the material, not of the object: a colour map of
/// two black-and-white stripe periods per image at `tile` 0.2 measures a period of 0.1 world
/// units on a cube of scale 0.35 and on one of 0.7 (`materials` density scene, as the
/// built-ins' test in `materials.rs`).
#[test]
fn pbr_texture_density_is_invariant_across_object_sizes() {
    let blenders = test_blenders("pbr_texture_density_is_invariant_across_object_sizes");
    if blenders.is_empty() {
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let mats = dir.path().join("mats");
    let stripes = pbr_folder(&mats, "stripes", PbrLayout::PolyHaven, [0, 0, 0]);
    let img = image::RgbImage::from_fn(64, 64, |x, _| {
        image::Rgb(if (x / 16) % 2 == 0 { [0; 3] } else { [255; 3] })
    });
    img.save(stripes.join("test_slug_diff_1k.png")).unwrap();
    std::fs::remove_file(stripes.join("test_slug_diff_1k.jpg")).unwrap();
    std::fs::write(stripes.join("material.json"), r#"{"tile": 0.2}"#).unwrap();
    let catalogue = run(&["materials", "json", "--materials", mats.to_str().unwrap()]);
    assert!(catalogue.status.success(), "{}", text(&catalogue));
    let bridge = BridgeDir::create(&String::from_utf8(catalogue.stdout).unwrap()).unwrap();
    let settings = MaterialSettings {
        mode: MaterialMode::Density,
        size: 400,
        samples: 4,
        displacement: 0.0,
        random: 0.37,
    };
    for blender in blenders {
        let out = dir
            .path()
            .join(format!("out-{}", blender.display()).replace('/', "_"));
        std::fs::create_dir(&out).unwrap();
        let mut session = Session::new(
            WorkerOptions::new(blender.clone(), &bridge, Arc::new(AtomicBool::new(false))),
            0,
            None,
        );
        let reply = session
            .request(&mut (), |w| {
                w.material(&settings, "stripes", &out, Duration::from_secs(600))
            })
            .unwrap_or_else(|e| panic!("{}: {e}", blender.display()));
        session.close();
        let m = &reply.measures;
        let (small, large) = (m["period_small"], m["period_large"]);
        eprintln!(
            "{}: stripe period small cube {small:.4}, large cube {large:.4} (world units)",
            blender.display()
        );
        assert!((small - 0.1).abs() < 0.01, "{m:?}");
        assert!((large - 0.1).abs() < 0.01, "{m:?}");
    }
}

/// The value of the header attribute `name` of type `kind` of the OpenEXR file `bytes`.
fn exr_attribute<'a>(bytes: &'a mut [u8], name: &str, kind: &str) -> &'a mut [u8] {
    let key = [name.as_bytes(), b"\0", kind.as_bytes(), b"\0"].concat();
    let at = bytes
        .windows(key.len())
        .position(|w| w == key.as_slice())
        .unwrap_or_else(|| panic!("no `{name}` in the EXR header"))
        + key.len();
    let size = u32::from_le_bytes(bytes[at..at + 4].try_into().unwrap()) as usize;
    &mut bytes[at + 4..at + 4 + size]
}

/// The 64 x 64 tiled OpenEXR file (one tile: what the `image` crate writes) `bytes` made to
/// claim `side` x `side` pixels in one tile: the header and its table of chunks agree, the
/// pixels do not.
fn exr_claiming(bytes: &mut [u8], side: i32) {
    for name in ["dataWindow", "displayWindow"] {
        let v = exr_attribute(bytes, name, "box2i");
        v[8..12].copy_from_slice(&(side - 1).to_le_bytes());
        v[12..16].copy_from_slice(&(side - 1).to_le_bytes());
    }
    let tiles = exr_attribute(bytes, "tiles", "tiledesc");
    tiles[0..4].copy_from_slice(&side.to_le_bytes());
    tiles[4..8].copy_from_slice(&side.to_le_bytes());
}

/// Issue 42, 8: every map a PBR material uses is decoded before a run, not only its header
/// read: a truncated JPEG colour map (which Blender renders silently) and an EXR
/// displacement map whose header claims 2048 x 2048 pixels but holds 64 x 64 (which failed
/// every image, exit 3, with a hint blaming `sample`) are refused before any image, naming
/// the material and the file, with a hint.
#[test]
fn pbr_maps_are_decoded_before_a_run() {
    let Some(blender) = crate::util::blender_or_skip("pbr_maps_are_decoded_before_a_run") else {
        return;
    };
    let generate = |mats: &Path| {
        let out = mats.parent().unwrap().join("out");
        let o = run(&[
            "generate",
            "--variant",
            "full",
            "-n",
            "1",
            "--width",
            "32",
            "--height",
            "24",
            "--samples",
            "2",
            "--workers",
            "1",
            "--blender",
            blender.to_str().unwrap(),
            "--materials",
            mats.to_str().unwrap(),
            "--out",
            out.to_str().unwrap(),
        ]);
        let pngs = std::fs::read_dir(out.join("clevrtex_full/0"))
            .into_iter()
            .flatten()
            .flatten()
            .filter(|e| e.path().extension().is_some_and(|x| x == "png"))
            .count();
        (o, pngs)
    };
    let check = |o: &std::process::Output, pngs: usize, want: &[&str]| {
        let t = text(o);
        assert_eq!(o.status.code(), Some(1), "{t}");
        assert_eq!(pngs, 0, "an image was rendered: {t}");
        let err = String::from_utf8_lossy(&o.stderr);
        for w in want.iter().chain(&["does not decode", "\nhint: "]) {
            assert!(err.contains(w), "`{w}` not in: {t}");
        }
    };
    let dir = tempfile::tempdir().unwrap();
    // A truncated JPEG: its header is whole, its pixels are not.
    let mats = dir.path().join("jpeg").join("mats");
    let wall = pbr_folder(&mats, "wall", PbrLayout::PolyHaven, [200, 40, 30]);
    let jpg = wall.join("test_slug_diff_1k.jpg");
    let mut bytes = std::fs::read(&jpg).unwrap();
    // Cut a few bytes into the entropy-coded data (after the start-of-scan segment).
    let sos = bytes.windows(2).position(|w| w == [0xff, 0xda]).unwrap();
    let len = usize::from(u16::from_be_bytes([bytes[sos + 2], bytes[sos + 3]]));
    bytes.truncate(sos + 2 + len + 8);
    std::fs::write(&jpg, bytes).unwrap();
    let (o, pngs) = generate(&mats);
    check(&o, pngs, &["`wall`", "test_slug_diff_1k.jpg"]);
    // An EXR whose header lies about its size.
    let mats = dir.path().join("exr").join("mats");
    let wall = pbr_folder(&mats, "wall", PbrLayout::PolyHaven, [200, 40, 30]);
    std::fs::remove_file(wall.join("test_slug_disp_1k.png")).unwrap();
    let exr = wall.join("test_slug_disp_1k.exr");
    image::Rgb32FImage::from_pixel(64, 64, image::Rgb([0.5, 0.5, 0.5]))
        .save(&exr)
        .unwrap();
    let mut bytes = std::fs::read(&exr).unwrap();
    exr_claiming(&mut bytes, 2048);
    std::fs::write(&exr, bytes).unwrap();
    let (o, pngs) = generate(&mats);
    check(&o, pngs, &["`wall`", "test_slug_disp_1k.exr"]);
}
