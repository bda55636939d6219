//! User materials in scenes (`--materials DIR`, issue 33): ClevrTex-convention `.blend`
//! node groups (built here in the real Blender by `tests/data/user_materials/make_blend.py`)
//! rendered by `generate` on Blender 3.4 and bpy 4.5 and seen on the albedo pass; the same
//! layouts with the built-in catalogue (masks byte-identical); and every bad input refused
//! before any image is rendered (exit 1, naming the material and the file).

use std::path::{Path, PathBuf};
use std::process::Command;

use crate::util::{blender_or_skip, data, run, test_blenders, text};

/// Build `DIR/<name>.blend` (node group `<name>`, texture `textures/<name>_COL_3K.<ext>`
/// of one sRGB colour) with `blender` (an executable, or a Python with `bpy`).
fn make_blend(blender: &Path, dir: &Path, name: &str, rgb: [u8; 3], ext: &str, mode: &str) {
    let script = data("user_materials/make_blend.py");
    let rgb = rgb.map(|c| c.to_string());
    // Started as the bridge is (`-b --factory-startup ... --python` or a Python with `bpy`);
    // the script reads its own arguments, the first seven after `--`.
    let mut args = vec![dir.as_os_str().to_owned()];
    args.extend([name, &rgb[0], &rgb[1], &rgb[2], ext, mode].map(std::ffi::OsString::from));
    let flavour = clevrtex_render::blender::flavour(blender);
    let out = clevrtex_render::blender::worker_command(blender, flavour, &script, &args)
        .output()
        .unwrap();
    assert!(
        out.status.success() && dir.join(format!("{name}.blend")).is_file(),
        "{}",
        text(&out)
    );
}

const RED: [u8; 3] = [200, 40, 40];
const BLUE: [u8; 3] = [40, 60, 200];

/// Two convention materials: `redstone` (PNG texture) and `bluetile` (JPEG texture).
fn library(blender: &Path, dir: &Path) {
    make_blend(blender, dir, "RedStone", RED, "png", "ok");
    make_blend(blender, dir, "BlueTile", BLUE, "jpg", "ok");
}

/// `generate` of tiny `full` images (`--variant full` unless `extra` has a `--config`).
fn generate(out: &Path, blender: &Path, extra: &[&str]) -> std::process::Output {
    let variant: &[&str] = if extra.contains(&"--config") {
        &[]
    } else {
        &["--variant", "full"]
    };
    let mut args = vec!["generate"];
    args.extend_from_slice(variant);
    args.extend([
        "--seed",
        "3",
        "--width",
        "64",
        "--height",
        "48",
        "--samples",
        "4",
        "--passes",
        "rgb,mask,albedo",
        "--workers",
        "1",
        "--blender",
        blender.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
    ]);
    args.extend_from_slice(extra);
    run(&args)
}

fn png(path: &Path) -> image::DynamicImage {
    image::open(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()))
}

/// `clevrtex generate --variant full --materials DIR -n 4` renders with the `.blend` node
/// groups: every object and the backdrop show their user material's texture colour on the
/// albedo pass; metadata and manifest record the materials with one hash each; `verify`
/// passes and shows them.
#[test]
fn generate_full_with_user_blend_materials_on_every_blender() {
    for blender in test_blenders("generate_full_with_user_blend_materials_on_every_blender") {
        let dir = tempfile::tempdir().unwrap();
        let lib = dir.path().join("lib");
        library(&blender, &lib);
        let out = dir.path().join("out");
        let o = generate(
            &out,
            &blender,
            &["-n", "4", "--materials", lib.to_str().unwrap()],
        );
        assert!(o.status.success(), "{}", text(&o));
        let vdir = out.join("clevrtex_full");
        let manifest: serde_json::Value =
            serde_json::from_slice(&std::fs::read(vdir.join("MANIFEST-0-4-0of1.json")).unwrap())
                .unwrap();
        let recorded = &manifest["user_materials"];
        assert_eq!(recorded["redstone"]["file"], "RedStone.blend", "{manifest}");
        assert_eq!(
            recorded["bluetile"]["textures"][0],
            "textures/BlueTile_COL_3K.jpg"
        );
        for i in 0..4 {
            let stem = format!("CLEVRTEX_full_{i:06}");
            let meta: serde_json::Value = serde_json::from_slice(
                &std::fs::read(vdir.join(format!("0/{stem}.json"))).unwrap(),
            )
            .unwrap();
            let mut names = vec![meta["ground_material"].as_str().unwrap().to_string()];
            for obj in meta["objects"].as_array().unwrap() {
                names.push(obj["material"].as_str().unwrap().to_string());
            }
            for n in &names {
                assert_eq!(
                    meta["user_materials"][n], recorded[n]["xxh3"],
                    "{n} in {stem}"
                );
            }
            let albedo = png(&vdir.join(format!("0/{stem}_albedo_0001.png"))).to_rgb8();
            let mask = png(&vdir.join(format!("0/{stem}_flat.png"))).to_luma8();
            // Id 0 is the backdrop, 1..N the objects in metadata order.
            for (id, name) in names.iter().enumerate() {
                let want = if name == "redstone" { RED } else { BLUE };
                let px: Vec<[u8; 3]> = mask
                    .enumerate_pixels()
                    .filter(|(_, _, m)| m.0[0] as usize == id)
                    .map(|(x, y, _)| albedo.get_pixel(x, y).0)
                    .collect();
                if px.is_empty() {
                    continue; // hidden at 64x48 below the visibility threshold
                }
                let close = px
                    .iter()
                    .filter(|p| (0..3).all(|c| p[c].abs_diff(want[c]) <= 8))
                    .count();
                assert!(
                    close * 2 > px.len(),
                    "{stem} id {id} ({name}): {close} of {} albedo pixels show {want:?} on {}",
                    px.len(),
                    blender.display()
                );
            }
        }
        let v = run(&["verify", out.to_str().unwrap()]);
        assert!(v.status.success(), "{}", text(&v));
        let shown = String::from_utf8_lossy(&v.stdout);
        assert!(shown.contains("user material redstone"), "{}", text(&v));
        // `report` lists them under "Provenance".
        let html = dir.path().join("report.html");
        let r = run(&[
            "report",
            out.to_str().unwrap(),
            "--out",
            html.to_str().unwrap(),
        ]);
        assert!(r.status.success(), "{}", text(&r));
        let page = std::fs::read_to_string(&html).unwrap();
        let hash = recorded["redstone"]["xxh3"].as_str().unwrap();
        assert!(
            page.contains("User materials") && page.contains(hash),
            "{}",
            text(&r)
        );
    }
}

/// The controlled comparison: the same seed with the built-in catalogue and with the user
/// library gives the same layouts and byte-identical masks, other materials. The backdrop's
/// true displacement is the material's own (as in the public generator) and can move a few
/// mask pixels at an object's foot (docs/materials.md), so this runs `full` with the backdrop
/// displacement off: then no geometry depends on the material.
#[test]
fn builtin_and_user_library_give_the_same_layouts_and_masks() {
    let Some(blender) = blender_or_skip("builtin_and_user_library_give_the_same_layouts_and_masks")
    else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let lib = dir.path().join("lib");
    library(&blender, &lib);
    let full = std::fs::read_to_string(crate::util::repo_root().join("configs/full.json")).unwrap();
    let mut config: serde_json::Value = serde_json::from_str(&full).unwrap();
    let background = config["background"].as_object_mut().unwrap();
    background.remove("displacement");
    let config_path = dir.path().join("full_flat.json");
    std::fs::write(&config_path, config.to_string()).unwrap();
    let c = config_path.to_str().unwrap();
    let (a, b) = (dir.path().join("builtin"), dir.path().join("user"));
    let o = generate(&a, &blender, &["-n", "2", "--config", c]);
    assert!(o.status.success(), "{}", text(&o));
    let lib_dir = lib.to_str().unwrap();
    let user = [
        "-n",
        "2",
        "--config",
        c,
        "--materials",
        lib_dir,
        "--material-set",
        "user",
    ];
    let o = generate(&b, &blender, &user);
    assert!(o.status.success(), "{}", text(&o));
    for i in 0..2 {
        let f = |root: &Path, suffix: &str| {
            std::fs::read(root.join(format!("clevrtex_full/0/CLEVRTEX_full_{i:06}{suffix}")))
                .unwrap()
        };
        assert!(f(&a, "_flat.png") == f(&b, "_flat.png"), "mask {i} differs");
        let meta = |root: &Path| -> serde_json::Value {
            serde_json::from_slice(&f(root, ".json")).unwrap()
        };
        let (ma, mb) = (meta(&a), meta(&b));
        for k in ["camera", "attempt"] {
            assert_eq!(ma[k], mb[k], "{k} of image {i}");
        }
        let objs = |m: &serde_json::Value| -> Vec<(serde_json::Value, serde_json::Value)> {
            m["objects"]
                .as_array()
                .unwrap()
                .iter()
                .map(|o| (o["3d_coords"].clone(), o["shape"].clone()))
                .collect()
        };
        assert_eq!(objs(&ma), objs(&mb), "image {i}");
        assert!(ma.get("user_materials").is_none());
        assert!(mb["ground_material"] == "redstone" || mb["ground_material"] == "bluetile");
    }
}

/// Run `generate` on the folder `lib` and expect exit 1 before any image, with `want` (and
/// the material's name) in the message.
fn refused(blender: &Path, lib: &Path, want: &[&str]) {
    let out = lib.parent().unwrap().join("out");
    let o = generate(
        &out,
        blender,
        &["-n", "1", "--materials", lib.to_str().unwrap()],
    );
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(1), "{}", text(&o));
    for w in want {
        assert!(err.contains(w), "`{w}` not in:\n{}", text(&o));
    }
    assert!(err.contains("\nhint: "), "{}", text(&o));
    let pngs = walk(&out)
        .into_iter()
        .filter(|p| p.extension().is_some_and(|e| e == "png"));
    assert_eq!(pngs.count(), 0, "an image was rendered: {}", text(&o));
}

fn walk(dir: &Path) -> Vec<PathBuf> {
    let mut out = Vec::new();
    for e in std::fs::read_dir(dir).into_iter().flatten().flatten() {
        let p = e.path();
        if p.is_dir() {
            out.extend(walk(&p));
        } else {
            out.push(p);
        }
    }
    out
}

/// A PNG claiming `w` x `h` pixels: its header, the start of its pixel data, its end (the
/// pixels themselves are not there: the claim alone must be refused).
fn png_header(w: u32, h: u32) -> Vec<u8> {
    let chunk = |kind: &[u8], data: &[u8]| {
        let mut body = kind.to_vec();
        body.extend(data);
        let mut out = (data.len() as u32).to_be_bytes().to_vec();
        out.extend(&body);
        out.extend(crc32fast::hash(&body).to_be_bytes());
        out
    };
    let mut ihdr = w.to_be_bytes().to_vec();
    ihdr.extend(h.to_be_bytes());
    ihdr.extend([8, 2, 0, 0, 0]);
    let mut out = b"\x89PNG\r\n\x1a\n".to_vec();
    out.extend(chunk(b"IHDR", &ihdr));
    out.extend(chunk(b"IDAT", &[0x78, 0x9c, 0x63, 0x60]));
    out.extend(chunk(b"IEND", &[]));
    out
}

/// Every bad input of the issue is refused before rendering, naming material and file.
#[test]
fn bad_user_materials_are_refused_before_rendering() {
    let Some(blender) = blender_or_skip("bad_user_materials_are_refused_before_rendering") else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let fresh = |name: &str| {
        let d = dir.path().join(name).join("lib");
        std::fs::create_dir_all(&d).unwrap();
        d
    };

    // Checked in Rust before Blender starts: a clash, a link out, a 2 GB `.blend`.
    let good = fresh("good");
    make_blend(&blender, &good, "BlueTile", BLUE, "jpg", "ok");
    let clash = fresh("clash");
    std::fs::copy(good.join("BlueTile.blend"), clash.join("bricks.blend")).unwrap();
    refused(&blender, &clash, &["bricks", "already defined"]);
    let link = fresh("link");
    std::os::unix::fs::symlink(good.join("BlueTile.blend"), link.join("Linked.blend")).unwrap();
    refused(
        &blender,
        &link,
        &["`linked`", "link out of the material folder"],
    );
    let huge = fresh("huge");
    let f = std::fs::File::create(huge.join("Huge.blend")).unwrap();
    std::io::Write::write_all(&mut &f, b"BLENDER-v304").unwrap();
    f.set_len(2 << 30).unwrap(); // sparse: 2 GB on paper
    refused(&blender, &huge, &["Huge.blend", "2147483648 bytes"]);

    // Found by inspecting the group in Blender, before any image.
    let nogroup = fresh("nogroup");
    make_blend(&blender, &nogroup, "Empty", BLUE, "png", "nogroup");
    refused(
        &blender,
        &nogroup,
        &["`empty`", "Empty.blend", "node group"],
    );
    let input = fresh("input");
    make_blend(&blender, &input, "Coated", BLUE, "png", "shaderinput");
    refused(&blender, &input, &["`coated`", "input `Coat`"]);
    let missing = fresh("missing");
    make_blend(&blender, &missing, "Gone", BLUE, "png", "ok");
    std::fs::remove_file(missing.join("textures/Gone_COL_3K.png")).unwrap();
    refused(
        &blender,
        &missing,
        &["`gone`", "Gone_COL_3K.png", "cannot be read"],
    );
    let corrupt = fresh("corrupt");
    make_blend(&blender, &corrupt, "Broken", BLUE, "jpg", "ok");
    let jpg = corrupt.join("textures/Broken_COL_3K.jpg");
    let mut bytes = std::fs::read(&jpg).unwrap();
    bytes.truncate(bytes.len() / 2);
    bytes.extend(std::iter::repeat_n(0x55u8, 64));
    std::fs::write(&jpg, bytes).unwrap();
    refused(
        &blender,
        &corrupt,
        &["`broken`", "Broken_COL_3K.jpg", "does not decode"],
    );
    let big = fresh("big");
    make_blend(&blender, &big, "Vast", BLUE, "png", "ok");
    std::fs::write(
        big.join("textures/Vast_COL_3K.png"),
        png_header(30_000, 30_000),
    )
    .unwrap();
    refused(
        &blender,
        &big,
        &["`vast`", "Vast_COL_3K.png", "30000x30000"],
    );
    // A texture outside the folder (an absolute path in the `.blend`, or a link out).
    let outside = fresh("outside");
    make_blend(&blender, &outside, "Far", BLUE, "png", "ok");
    let tex = outside.join("textures/Far_COL_3K.png");
    std::fs::rename(&tex, dir.path().join("Far_COL_3K.png")).unwrap();
    std::os::unix::fs::symlink(dir.path().join("Far_COL_3K.png"), &tex).unwrap();
    refused(
        &blender,
        &outside,
        &["`far`", "outside the material folder"],
    );
}

/// The public generator's own `data/materials` holds `Rubber.blend` and `MyMetal.blend`
/// (CLEVR's two base materials, which every textured variant's config excludes) beside the
/// textured groups; `Rubber.blend` would clash with our built-in `rubber`. They are left out
/// of set `user`, said in one line on stderr: `generate --variant full --materials` works on
/// such a folder and draws only the textured group. A config may exclude them (the
/// generator's configs do) but not include them; another clash is still an error.
#[test]
fn the_generators_clevr_base_materials_are_left_out_of_the_user_set() {
    let Some(blender) =
        blender_or_skip("the_generators_clevr_base_materials_are_left_out_of_the_user_set")
    else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let lib = dir.path().join("lib");
    make_blend(&blender, &lib, "RedStone", RED, "png", "ok");
    make_blend(&blender, &lib, "Rubber", BLUE, "png", "ok");
    make_blend(&blender, &lib, "MyMetal", BLUE, "jpg", "ok");
    let out = dir.path().join("out");
    let o = generate(
        &out,
        &blender,
        &["-n", "2", "--materials", lib.to_str().unwrap()],
    );
    assert!(o.status.success(), "{}", text(&o));
    let err = String::from_utf8_lossy(&o.stderr);
    let notes: Vec<&str> = err.lines().filter(|l| l.starts_with("note: ")).collect();
    assert_eq!(notes.len(), 1, "{}", text(&o));
    for want in [
        "MyMetal.blend`",
        "Rubber.blend`",
        "CLEVR base materials",
        "left out of set `user`",
        "built-in `metal`, `rubber`",
    ] {
        assert!(notes[0].contains(want), "`{want}` not in {}", notes[0]);
    }
    let vdir = out.join("clevrtex_full");
    let manifest: serde_json::Value =
        serde_json::from_slice(&std::fs::read(vdir.join("MANIFEST-0-2-0of1.json")).unwrap())
            .unwrap();
    let recorded: Vec<&String> = manifest["user_materials"]
        .as_object()
        .unwrap()
        .keys()
        .collect();
    assert_eq!(recorded, ["redstone"], "{manifest}");
    for i in 0..2 {
        let meta: serde_json::Value = serde_json::from_slice(
            &std::fs::read(vdir.join(format!("0/CLEVRTEX_full_{i:06}.json"))).unwrap(),
        )
        .unwrap();
        assert_eq!(meta["ground_material"], "redstone", "image {i}");
        for obj in meta["objects"].as_array().unwrap() {
            assert_eq!(obj["material"], "redstone", "image {i}");
        }
    }

    // A config in the generator's manner excludes them; one that includes `mymetal` is told
    // what it is and which built-in plays its part (checked by `sample`: nothing renders).
    let config = |name: &str, materials: serde_json::Value| {
        let full =
            std::fs::read_to_string(crate::util::repo_root().join("configs/full.json")).unwrap();
        let mut c: serde_json::Value = serde_json::from_str(&full).unwrap();
        c["objects"]["materials"] = materials;
        let path = dir.path().join(name);
        std::fs::write(&path, c.to_string()).unwrap();
        path
    };
    let sample = |config: &Path| {
        run(&[
            "sample",
            "-n",
            "1",
            "--config",
            config.to_str().unwrap(),
            "--materials",
            lib.to_str().unwrap(),
            "--out",
            dir.path().join("scenes").to_str().unwrap(),
        ])
    };
    let excluding = config(
        "excluding.json",
        serde_json::json!({"sets": ["user"], "exclude": ["tabularasa", "rubber", "mymetal"]}),
    );
    let o = sample(&excluding);
    assert!(o.status.success(), "{}", text(&o));
    let including = config(
        "including.json",
        serde_json::json!({"include": ["mymetal"]}),
    );
    let o = sample(&including);
    assert_eq!(o.status.code(), Some(1), "{}", text(&o));
    let err = String::from_utf8_lossy(&o.stderr);
    for want in ["`mymetal`", "MyMetal.blend", "built-in `metal`", "\nhint: "] {
        assert!(err.contains(want), "`{want}` not in:\n{}", text(&o));
    }

    // Any other name of a built-in is still a clash, naming both files, before rendering.
    let clash = dir.path().join("clash").join("lib");
    std::fs::create_dir_all(&clash).unwrap();
    std::fs::copy(lib.join("Rubber.blend"), clash.join("Rubber.blend")).unwrap();
    std::fs::copy(lib.join("RedStone.blend"), clash.join("Plain.blend")).unwrap();
    refused(
        &blender,
        &clash,
        &[
            "Plain.blend",
            "`plain`",
            "already defined by `basic/plain.json`",
        ],
    );
}

/// `bench render --materials DIR` end to end on Blender 3.4 (tiny): the bench scene draws its
/// textured materials from the folder, renders and writes its row; a texture edited in place
/// renders a new reference (the reference cache is keyed by the user materials' contents,
/// not only their paths).
#[test]
fn bench_render_with_user_materials_end_to_end() {
    let Some(blender) = blender_or_skip("bench_render_with_user_materials_end_to_end") else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let lib = dir.path().join("lib");
    make_blend(&blender, &lib, "RedStone", RED, "png", "ok");
    let out = dir.path().join("bench");
    let bench = || {
        run(&[
            "bench",
            "render",
            "--quick",
            "--scenes",
            "1",
            "--width",
            "24",
            "--height",
            "16",
            "--reference-samples",
            "8",
            "--only",
            "fixed-4",
            "--threads",
            "1",
            "--blender",
            blender.to_str().unwrap(),
            "--materials",
            lib.to_str().unwrap(),
            "--out",
            out.to_str().unwrap(),
        ])
    };
    let o = bench();
    let t = text(&o);
    assert!(o.status.success(), "{t}");
    assert!(t.contains("rendering the reference (8 samples)"), "{t}");
    let scene: serde_json::Value =
        serde_json::from_slice(&std::fs::read(out.join("runs/00-fixed-4/scene.json")).unwrap())
            .unwrap();
    assert_eq!(scene["backdrop"]["material"]["name"], "redstone", "{scene}");
    for obj in scene["objects"].as_array().unwrap() {
        assert_eq!(obj["material"]["name"], "redstone", "{scene}");
    }
    let csv = std::fs::read_to_string(out.join("bench-render.csv")).unwrap();
    assert_eq!(csv.lines().count(), 2, "{csv}");
    assert!(csv.lines().nth(1).unwrap().starts_with("full#0,"), "{csv}");

    // The same texture file with other pixels: not the cached reference.
    image::RgbImage::from_pixel(8, 8, image::Rgb(BLUE))
        .save(lib.join("textures/RedStone_COL_3K.png"))
        .unwrap();
    let o = bench();
    let t = text(&o);
    assert!(o.status.success(), "{t}");
    assert!(
        t.contains("rendering the reference") && !t.contains("reference cached"),
        "{t}"
    );
    let refs = std::fs::read_dir(out.join("references")).unwrap().count();
    assert_eq!(refs, 2);
}

/// Image `i` of `generate`'s `clevrtex_full` folder `vdir`: for the backdrop and each object
/// (mask ids in metadata order), its material's name and the albedo pixels it covers.
fn albedo_by_material(vdir: &Path, i: u64) -> Vec<(String, Vec<[u8; 3]>)> {
    let stem = format!("CLEVRTEX_full_{i:06}");
    let meta: serde_json::Value =
        serde_json::from_slice(&std::fs::read(vdir.join(format!("0/{stem}.json"))).unwrap())
            .unwrap();
    let mut names = vec![meta["ground_material"].as_str().unwrap().to_string()];
    for obj in meta["objects"].as_array().unwrap() {
        names.push(obj["material"].as_str().unwrap().to_string());
    }
    let albedo = png(&vdir.join(format!("0/{stem}_albedo_0001.png"))).to_rgb8();
    let mask = png(&vdir.join(format!("0/{stem}_flat.png"))).to_luma8();
    (0..)
        .zip(names)
        .map(|(id, name)| {
            let px = mask
                .enumerate_pixels()
                .filter(|(_, _, m)| usize::from(m.0[0]) == id)
                .map(|(x, y, _)| albedo.get_pixel(x, y).0)
                .collect();
            (name, px)
        })
        .collect()
}

/// Whether most of `px` show `want` (albedo within 8 levels).
fn mostly(px: &[[u8; 3]], want: [u8; 3]) -> bool {
    let close = px
        .iter()
        .filter(|p| (0..3).all(|c| p[c].abs_diff(want[c]) <= 8))
        .count();
    close * 2 > px.len()
}

/// Issue 42, 2: a user material's content hash is a setting of the run. A texture edited
/// between a run and its resume into the same folder is refused like another `--seed`
/// (before, the resume mixed two materials under one name and rewrote the manifest), and
/// `verify` compares the hash each sample records with its manifest's.
#[test]
fn an_edited_user_material_is_a_setting_for_resume_and_verify() {
    let Some(blender) =
        blender_or_skip("an_edited_user_material_is_a_setting_for_resume_and_verify")
    else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let lib = dir.path().join("lib");
    library(&blender, &lib);
    let out = dir.path().join("out");
    let materials = ["--materials", lib.to_str().unwrap()];
    let o = generate(&out, &blender, &[&["-n", "1"][..], &materials].concat());
    assert!(o.status.success(), "{}", text(&o));
    let vdir = out.join("clevrtex_full");
    let first = std::fs::read(vdir.join("MANIFEST-0-1-0of1.json")).unwrap();

    // The texture edited, then the run resumed and grown: refused before any image.
    image::RgbImage::from_pixel(8, 8, image::Rgb([10, 200, 10]))
        .save(lib.join("textures/RedStone_COL_3K.png"))
        .unwrap();
    let o = generate(
        &out,
        &blender,
        &[&["-n", "2", "--allow-split-mismatch"][..], &materials].concat(),
    );
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(1), "{}", text(&o));
    assert!(
        err.contains("with other settings") && err.contains("user material `redstone` hash"),
        "{}",
        text(&o)
    );
    assert!(!vdir.join("0/CLEVRTEX_full_000001.json").exists());
    assert_eq!(
        std::fs::read(vdir.join("MANIFEST-0-1-0of1.json")).unwrap(),
        first
    );

    // A manifest whose user materials are not the ones its samples record: `verify` fails.
    let v = run(&["verify", out.to_str().unwrap()]);
    assert!(v.status.success(), "{}", text(&v));
    let mut m: serde_json::Value = serde_json::from_slice(&first).unwrap();
    for (_, u) in m["user_materials"].as_object_mut().unwrap() {
        u["xxh3"] = "0123456789abcdef".into();
    }
    std::fs::write(
        vdir.join("MANIFEST-0-1-0of1.json"),
        serde_json::to_vec(&m).unwrap(),
    )
    .unwrap();
    let v = run(&["verify", out.to_str().unwrap()]);
    let shown = text(&v);
    assert!(!v.status.success(), "{shown}");
    assert!(
        shown.contains("vs hash 0123456789abcdef") || shown.contains("hash 0123456789abcdef vs"),
        "{shown}"
    );
}

/// Issue 42, 3: Blender reads exactly the bytes that were checked. The texture is replaced
/// by a link out of the folder (to an image of another colour) as soon as the run has
/// checked its materials (its plan is written after the checks, before any worker renders):
/// the images still show the checked texture, and the manifest's hash is the checked one.
#[test]
fn a_texture_swapped_after_the_check_never_reaches_blender() {
    let Some(blender) = blender_or_skip("a_texture_swapped_after_the_check_never_reaches_blender")
    else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let lib = dir.path().join("lib");
    make_blend(&blender, &lib, "RedStone", RED, "png", "ok");
    let outside = dir.path().join("outside.png");
    image::RgbImage::from_pixel(8, 8, image::Rgb(BLUE))
        .save(&outside)
        .unwrap();
    let out = dir.path().join("out");
    let b = blender.to_str().unwrap();
    let (o, l) = (out.to_str().unwrap(), lib.to_str().unwrap());
    let mut child = Command::new(env!("CARGO_BIN_EXE_clevrtex"))
        .args([
            "generate",
            "--variant",
            "full",
            "--seed",
            "3",
            "-n",
            "2",
            "--width",
            "32",
            "--height",
            "24",
            "--samples",
            "2",
            "--passes",
            "rgb,mask,albedo",
            "--workers",
            "1",
            "--blender",
            b,
            "--materials",
            l,
            "--out",
            o,
        ])
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    let plan = out.join("clevrtex_full/MANIFEST-0-2-0of1.json");
    let start = std::time::Instant::now();
    while !plan.exists() {
        assert!(
            child.try_wait().unwrap().is_none(),
            "generate ended before its plan"
        );
        assert!(start.elapsed().as_secs() < 300, "no plan written");
        std::thread::sleep(std::time::Duration::from_millis(2));
    }
    let tex = lib.join("textures/RedStone_COL_3K.png");
    std::fs::remove_file(&tex).unwrap();
    std::os::unix::fs::symlink(&outside, &tex).unwrap();
    let done = child.wait_with_output().unwrap();
    assert!(done.status.success(), "{}", text(&done));
    let vdir = out.join("clevrtex_full");
    for i in 0..2 {
        for (name, px) in albedo_by_material(&vdir, i) {
            assert!(
                px.is_empty() || mostly(&px, RED),
                "image {i}, {name}: the swapped texture was rendered"
            );
        }
    }
    let v = run(&["verify", o]);
    assert!(v.status.success(), "{}", text(&v));
}

/// A JSON material of `layers` (one `image` layer reading `path`) in `lib`.
fn json_image_material(lib: &Path, name: &str, path: &str) {
    std::fs::create_dir_all(lib).unwrap();
    let m = serde_json::json!({
        "description": "an image layer",
        "layers": [{"block": "image", "path": path}],
    });
    std::fs::write(lib.join(format!("{name}.json")), m.to_string()).unwrap();
}

/// Issue 42, 4: a JSON material's `image` layers pass the checks of a `.blend`'s textures
/// (inside the folder, a regular file, a format, the side cap, decoding), and the manifest
/// records the texture relative to the folder.
#[test]
fn json_material_images_pass_the_texture_checks() {
    let Some(blender) = blender_or_skip("json_material_images_pass_the_texture_checks") else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let fresh = |name: &str| {
        let d = dir.path().join(name).join("lib");
        std::fs::create_dir_all(d.join("tex")).unwrap();
        d
    };
    let good = fresh("good");
    image::RgbImage::from_pixel(8, 8, image::Rgb(RED))
        .save(good.join("tex/ok.png"))
        .unwrap();
    json_image_material(&good, "Okimage", "tex/ok.png");
    let out = good.parent().unwrap().join("out");
    let o = generate(
        &out,
        &blender,
        &["-n", "1", "--materials", good.to_str().unwrap()],
    );
    assert!(o.status.success(), "{}", text(&o));
    let manifest: serde_json::Value = serde_json::from_slice(
        &std::fs::read(out.join("clevrtex_full/MANIFEST-0-1-0of1.json")).unwrap(),
    )
    .unwrap();
    let entry = &manifest["user_materials"]["okimage"];
    assert_eq!(entry["file"], "Okimage.json", "{manifest}");
    assert_eq!(
        entry["textures"],
        serde_json::json!(["tex/ok.png"]),
        "{manifest}"
    );

    // Out of the folder by `..`, by a link, by an absolute path to a device.
    let secret = dir.path().join("secret.png");
    image::RgbImage::from_pixel(8, 8, image::Rgb(BLUE))
        .save(&secret)
        .unwrap();
    let up = fresh("up");
    json_image_material(&up, "Up", "../../secret.png");
    refused(&blender, &up, &["`up`", "outside the material folder"]);
    let link = fresh("link");
    std::os::unix::fs::symlink(&secret, link.join("tex/in.png")).unwrap();
    json_image_material(&link, "Linked", "tex/in.png");
    refused(
        &blender,
        &link,
        &["`linked`", "outside the material folder"],
    );
    let dev = fresh("dev");
    json_image_material(&dev, "Zero", "/dev/zero");
    refused(&blender, &dev, &["/dev/zero", "not a regular file"]);
    let fifo = fresh("fifo");
    let made = Command::new("mkfifo").arg(fifo.join("tex/f.png")).status();
    assert!(made.is_ok_and(|s| s.success()), "mkfifo");
    json_image_material(&fifo, "Fifo", "tex/f.png");
    refused(&blender, &fifo, &["tex/f.png", "not a regular file"]);
    // Over the side cap, and not an image at all.
    let big = fresh("big");
    std::fs::write(big.join("tex/big.png"), png_header(16_384, 16_384)).unwrap();
    json_image_material(&big, "Big", "tex/big.png");
    refused(&blender, &big, &["`big`", "big.png", "16384x16384"]);
    let text_file = fresh("text");
    std::fs::write(text_file.join("tex/t.png"), b"hello").unwrap();
    json_image_material(&text_file, "Words", "tex/t.png");
    refused(
        &blender,
        &text_file,
        &["`words`", "t.png", "is not a PNG, JPEG or TIFF"],
    );
}

/// Issue 42, 5: an image packed into a `.blend` is checked like a file (its bytes written out
/// by the bridge, no pixels decoded in Blender): a packed PNG claiming 16384 x 16384 pixels
/// is refused before any image; a small packed texture renders, from the checked bytes.
#[test]
fn packed_images_are_checked_like_files() {
    let Some(blender) = blender_or_skip("packed_images_are_checked_like_files") else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let huge = dir.path().join("huge").join("lib");
    make_blend(&blender, &huge, "Packedhuge", BLUE, "png", "packedhuge");
    refused(
        &blender,
        &huge,
        &["`packedhuge`", "packed into the `.blend`", "16384x16384"],
    );
    let lib = dir.path().join("ok").join("lib");
    make_blend(&blender, &lib, "Packedred", RED, "png", "packed");
    assert!(!lib.join("textures/Packedred_COL_3K.png").exists());
    let out = dir.path().join("out");
    let o = generate(
        &out,
        &blender,
        &["-n", "1", "--materials", lib.to_str().unwrap()],
    );
    assert!(o.status.success(), "{}", text(&o));
    for (name, px) in albedo_by_material(&out.join("clevrtex_full"), 0) {
        assert!(px.is_empty() || mostly(&px, RED), "{name}");
    }
}

/// Issue 42, 6: two `.blend` files whose node groups share a name (the public generator's
/// files are often copies of one another) both render, each with its own group; identical
/// files have the same hash (the name Blender gives a second group loaded, `Okmat.001`, is
/// not part of it).
#[test]
fn groups_of_the_same_name_in_two_files_render_each_its_own() {
    let Some(blender) = blender_or_skip("groups_of_the_same_name_in_two_files_render_each_its_own")
    else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let (red, blue) = (dir.path().join("red"), dir.path().join("blue"));
    make_blend(&blender, &red, "Okmat", RED, "png", "ok");
    make_blend(&blender, &blue, "Okmat", BLUE, "jpg", "ok");
    let lib = dir.path().join("lib");
    std::fs::create_dir_all(lib.join("textures")).unwrap();
    std::fs::copy(red.join("Okmat.blend"), lib.join("Alpha.blend")).unwrap();
    std::fs::copy(red.join("Okmat.blend"), lib.join("Alphacopy.blend")).unwrap();
    std::fs::copy(blue.join("Okmat.blend"), lib.join("Beta.blend")).unwrap();
    for (from, f) in [(&red, "Okmat_COL_3K.png"), (&blue, "Okmat_COL_3K.jpg")] {
        std::fs::copy(from.join("textures").join(f), lib.join("textures").join(f)).unwrap();
    }
    let out = dir.path().join("out");
    let o = generate(
        &out,
        &blender,
        &["-n", "2", "--materials", lib.to_str().unwrap()],
    );
    assert!(o.status.success(), "{}", text(&o));
    let vdir = out.join("clevrtex_full");
    let manifest: serde_json::Value =
        serde_json::from_slice(&std::fs::read(vdir.join("MANIFEST-0-2-0of1.json")).unwrap())
            .unwrap();
    let um = &manifest["user_materials"];
    assert_eq!(um["alpha"]["group"], "Okmat", "{manifest}");
    assert_eq!(um["beta"]["group"], "Okmat", "{manifest}");
    assert_eq!(um["alpha"]["xxh3"], um["alphacopy"]["xxh3"], "{manifest}");
    assert_ne!(um["alpha"]["xxh3"], um["beta"]["xxh3"], "{manifest}");
    let mut seen = std::collections::BTreeSet::new();
    for i in 0..2 {
        for (name, px) in albedo_by_material(&vdir, i) {
            let want = if name == "beta" { BLUE } else { RED };
            assert!(px.is_empty() || mostly(&px, want), "image {i}, {name}");
            seen.insert(name);
        }
    }
    assert!(seen.contains("beta"), "{seen:?}");
}

/// Issue 43, 5: a `.blend` library whose textures are missing (the public generator's
/// folder without its textures) is named whole before anything renders, by `generate` and
/// `materials check` alike: the count and every missing texture, not the first alone (more
/// than ten are cut to ten and counted: the unit test of `user_materials::summary`).
#[test]
fn every_missing_texture_of_a_library_is_named_at_once() {
    let Some(blender) = blender_or_skip("every_missing_texture_of_a_library_is_named_at_once")
    else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let lib = dir.path().join("lib");
    std::fs::create_dir_all(&lib).unwrap();
    let names = ["GoneA", "GoneB", "GoneC"];
    for n in names {
        make_blend(&blender, &lib, n, RED, "png", "ok");
    }
    std::fs::remove_dir_all(lib.join("textures")).unwrap();
    let o = Command::new(env!("CARGO_BIN_EXE_clevrtex"))
        .args(["materials", "check", "--set", "user", "--materials"])
        .arg(&lib)
        .arg("--blender")
        .arg(&blender)
        .output()
        .unwrap();
    let t = text(&o);
    assert_eq!(o.status.code(), Some(1), "{t}");
    assert!(
        t.contains("3 files of user materials failed their checks"),
        "{t}"
    );
    for n in names {
        assert!(t.contains(&format!("{n}_COL_3K.png")), "{n} not named: {t}");
    }
    assert!(t.contains("hint: "), "{t}");
    // `generate` refuses the same library with the same list, before any image.
    let out = dir.path().join("out");
    let o = generate(
        &out,
        &blender,
        &[
            "-n",
            "1",
            "--materials",
            lib.to_str().unwrap(),
            "--material-set",
            "user",
        ],
    );
    let t = text(&o);
    assert_eq!(o.status.code(), Some(1), "{t}");
    assert!(
        t.contains("3 files of user materials failed their checks"),
        "{t}"
    );
    assert!(
        walk(&out)
            .iter()
            .all(|p| !p.to_string_lossy().ends_with(".png")),
        "{t}"
    );
}

/// Issue 48: a FIFO named like a material (`x.json`, `y.blend`) in `--materials` is refused,
/// named, without blocking: `materials list`, `sample` and `generate` hung for good opening it.
#[test]
fn a_fifo_in_the_material_folder_is_refused_without_blocking() {
    let tmp = tempfile::tempdir().unwrap();
    for name in ["x.json", "y.blend"] {
        let lib = tmp.path().join(name.replace('.', "_"));
        std::fs::create_dir_all(&lib).unwrap();
        let fifo = lib.join(name);
        let st = Command::new("mkfifo").arg(&fifo).status().unwrap();
        assert!(st.success());
        let out = tmp.path().join("out");
        let l = lib.as_os_str();
        let o_s = out.as_os_str();
        for args in [
            vec![
                "materials".as_ref(),
                "--materials".as_ref(),
                l,
                "list".as_ref(),
            ],
            vec![
                "sample".as_ref(),
                "--variant".as_ref(),
                "full".as_ref(),
                "-n".as_ref(),
                "1".as_ref(),
                "--materials".as_ref(),
                l,
                "--out".as_ref(),
                o_s,
            ],
            vec![
                "generate".as_ref(),
                "-n".as_ref(),
                "1".as_ref(),
                "--materials".as_ref(),
                l,
                "--blender".as_ref(),
                "/nonexistent/blender".as_ref(),
                "--out".as_ref(),
                o_s,
            ],
        ] {
            let o = crate::util::run_within(&args, 30);
            let t = text(&o);
            assert_eq!(o.status.code(), Some(1), "{args:?}: {t}");
            assert!(
                t.contains(name) && t.contains("not a regular file"),
                "{args:?}: {t}"
            );
        }
    }
}
