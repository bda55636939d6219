//! Integration tests for `clevrtex materials`.

use std::path::Path;
use std::process::Command;
use std::sync::atomic::AtomicBool;
use std::sync::Arc;
use std::time::Duration;

use clevrtex_render::{BridgeDir, MaterialMode, MaterialSettings, Session, WorkerOptions};

use crate::util::{
    blender_or_skip, blender_wrapper, clevrtex, crash_once_then, fake_blender, run, text,
};

fn write(dir: &Path, name: &str, body: &str) {
    std::fs::write(dir.join(name), body).unwrap();
}

#[test]
fn list_shows_every_material_with_set_and_displacement() {
    let out = run(&["materials", "list"]);
    assert!(out.status.success(), "{}", text(&out));
    let stdout = String::from_utf8_lossy(&out.stdout);
    let rows: Vec<&str> = stdout.lines().skip(1).collect();
    assert_eq!(rows.len(), 3 + 1 + 61 + 25, "{stdout}");
    let row = |name: &str| {
        rows.iter()
            .find(|r| r.split_whitespace().next() == Some(name))
            .unwrap_or_else(|| panic!("`{name}` missing:\n{stdout}"))
            .split_whitespace()
            .take(3)
            .collect::<Vec<_>>()
    };
    assert_eq!(row("bricks"), ["bricks", "main", "yes"]);
    assert_eq!(row("plain"), ["plain", "basic", "no"]);
    assert_eq!(row("mossy_forest_grass")[1], "background");
}

#[test]
fn malformed_material_files_fail_with_file_and_field() {
    let cases = [
        (
            r#"{"description": "d", "layers": [{"block": "bricks", "size": [1, 2]}]}"#,
            "layers[0].size",
        ),
        (
            r#"{"description": "d", "layers": [{"block": "brickz"}]}"#,
            "layers[0].block",
        ),
        (
            r##"{"description": "d", "layers": [{"block": "solid", "colors": ["red"]}]}"##,
            "layers[0].colors[0]",
        ),
        (
            r#"{"description": "d", "layers": [{"block": "solid"}], "surfaces": {}}"#,
            "surfaces",
        ),
        (
            r#"{"description": "d", "layers": [{"block": "graph", "nodes": {}, "links": [["coord", "n.Vector"]]}]}"#,
            "layers[0].links[0][1]",
        ),
    ];
    for (body, field) in cases {
        let dir = tempfile::tempdir().unwrap();
        write(dir.path(), "broken.json", body);
        let out = run(&[
            "materials",
            "list",
            "--materials",
            dir.path().to_str().unwrap(),
        ]);
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(1), "{}", text(&out));
        assert!(stderr.contains("broken.json"), "no file in: {stderr}");
        assert!(
            stderr.contains(&format!("field `{field}`")),
            "no field `{field}` in: {stderr}"
        );
        assert!(stderr.contains("hint: "), "no hint in: {stderr}");
        assert!(!stderr.contains("panicked"), "{stderr}");
    }
}

#[test]
fn user_names_must_not_clash() {
    let dir = tempfile::tempdir().unwrap();
    write(
        dir.path(),
        "bricks.json",
        r#"{"description": "d", "layers": [{"block": "solid"}]}"#,
    );
    let out = run(&[
        "materials",
        "list",
        "--materials",
        dir.path().to_str().unwrap(),
    ]);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(1), "{}", text(&out));
    assert!(
        stderr.contains("`bricks` is already defined by `main/bricks.json`"),
        "{stderr}"
    );
}

/// Every catalogue entry builds in real Blender and renders with no error and no pink
/// (missing texture) pixel. One Blender process for all of them.
/// The bridge's block table (`BLOCKS` in `blender_scripts/material_blocks.py`) implements
/// exactly the blocks of the schema (`materials/blocks.json`): a block the schema accepts but
/// the bridge lacks would only fail inside Blender, one the bridge has but the schema lacks
/// could never be used.
#[test]
fn bridge_block_table_matches_the_block_schema() {
    let path = crate::util::repo_root().join("blender_scripts/material_blocks.py");
    let source = std::fs::read_to_string(&path).unwrap();
    let mut lines = source
        .lines()
        .skip_while(|l| l.trim_end() != "BLOCKS = {")
        .skip(1);
    let mut bridge = Vec::new();
    for line in lines.by_ref() {
        let line = line.trim();
        if line == "}" {
            break;
        }
        let name = line
            .strip_prefix('"')
            .and_then(|l| l.split_once("\":"))
            .map(|(name, _)| name.to_string())
            .unwrap_or_else(|| panic!("unexpected line in BLOCKS of {}: `{line}`", path.display()));
        bridge.push(name);
    }
    assert!(
        !bridge.is_empty(),
        "no `BLOCKS = {{` table in {}",
        path.display()
    );
    bridge.sort();
    let schema: serde_json::Value = serde_json::from_str(clevrtex_materials::BLOCKS_JSON).unwrap();
    let mut schema: Vec<String> = schema["blocks"]
        .as_object()
        .expect("blocks.json has a `blocks` object")
        .keys()
        .cloned()
        .collect();
    schema.sort();
    assert_eq!(
        bridge, schema,
        "blender_scripts/material_blocks.py BLOCKS vs materials/blocks.json `blocks`"
    );
}

#[test]
fn every_material_builds_and_renders_in_blender() {
    if blender_or_skip("every_material_builds_and_renders_in_blender").is_none() {
        return;
    }
    let out = run(&["materials", "check", "--set", "all"]);
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(out.status.success(), "{}", text(&out));
    let ok = stdout.lines().filter(|l| l.starts_with("ok ")).count();
    assert_eq!(ok, 90, "{stdout}");
}

/// The texture density is a property of the material, not of the object: stripes of
/// period 0.1 world units measure 0.1 on a cube of scale 0.35 and on one of scale 0.7 (with
/// plain Object coordinates they would measure 0.035 and 0.07).
#[test]
fn texture_density_is_invariant_across_object_sizes() {
    let Some(blender) = blender_or_skip("texture_density_is_invariant_across_object_sizes") else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let mats = dir.path().join("mats");
    std::fs::create_dir(&mats).unwrap();
    write(
        &mats,
        "stripes.json",
        r##"{"description": "test stripes", "layers": [{"block": "waves", "period": 0.1,
            "direction": [1, 0, 0], "profile": "square", "colors": ["#000000", "#ffffff"],
            "variation": 0}]}"##,
    );
    let json = run(&["materials", "json", "--materials", mats.to_str().unwrap()]);
    assert!(json.status.success(), "{}", text(&json));
    // The worker's `material` request, as `clevrtex materials` sends it.
    let bridge = BridgeDir::create(&String::from_utf8(json.stdout).unwrap()).unwrap();
    let mut session = Session::new(
        WorkerOptions::new(blender, &bridge, Arc::new(AtomicBool::new(false))),
        0,
        None,
    );
    let settings = MaterialSettings {
        mode: MaterialMode::Density,
        size: 400,
        samples: 4,
        displacement: 0.0,
        random: 0.37,
    };
    let out = dir.path().join("out");
    std::fs::create_dir(&out).unwrap();
    let replies: Vec<_> = ["stripes", "bricks"]
        .iter()
        .map(|name| {
            session
                .request(&mut (), |w| {
                    w.material(&settings, name, &out, Duration::from_secs(600))
                })
                .unwrap_or_else(|e| panic!("{name}: {e}"))
        })
        .collect();
    session.close();
    assert_eq!(replies.len(), 2);
    let stripes = &replies[0].measures;
    let (small, large) = (stripes["period_small"], stripes["period_large"]);
    eprintln!("stripe period: small cube {small:.4}, large cube {large:.4} (world units)");
    assert!((small - 0.1).abs() < 0.01, "{stripes:?}");
    assert!((large - 0.1).abs() < 0.01, "{stripes:?}");
    // The large cube shows about twice as many stripes as the small one.
    let flips = |k: &str| stripes[k];
    let ratio = flips("flips_large") / flips("flips_small");
    assert!((1.7..2.4).contains(&ratio), "{stripes:?}");
    // Bricks: the mortar-line period along x agrees between sizes too.
    let b = &replies[1].measures;
    let (bs, bl) = (b["period_small"], b["period_large"]);
    assert!((bs / bl - 1.0).abs() < 0.3, "{b:?}");
}

const MAKE_BLEND: &str = r#"
import bpy, sys
path = sys.argv[sys.argv.index("--") + 1]
ng = bpy.data.node_groups.new("UserMaterial", "ShaderNodeTree")
for name, kind in (("Color", "NodeSocketColor"), ("Random", "NodeSocketFloat"),
                   ("Displacement", "NodeSocketFloat"), ("Scale", "NodeSocketFloat")):
    ng.inputs.new(kind, name)
ng.outputs.new("NodeSocketShader", "Shader")
ng.outputs.new("NodeSocketVector", "Displacement")
gi = ng.nodes.new("NodeGroupInput")
go = ng.nodes.new("NodeGroupOutput")
bsdf = ng.nodes.new("ShaderNodeBsdfPrincipled")
checker = ng.nodes.new("ShaderNodeTexChecker")
ng.links.new(gi.outputs["Scale"], checker.inputs["Scale"])
ng.links.new(gi.outputs["Color"], checker.inputs["Color1"])
ng.links.new(checker.outputs["Color"], bsdf.inputs["Base Color"])
ng.links.new(bsdf.outputs["BSDF"], go.inputs["Shader"])
disp = ng.nodes.new("ShaderNodeDisplacement")
ng.links.new(gi.outputs["Displacement"], disp.inputs["Scale"])
ng.links.new(checker.outputs["Fac"], disp.inputs["Height"])
ng.links.new(disp.outputs["Displacement"], go.inputs["Displacement"])
ng.use_fake_user = True
bpy.ops.wm.save_as_mainfile(filepath=path)
"#;

/// A user `.blend` with a ClevrTex-style node group is picked up by `--materials DIR` and
/// renders through the same bridge code as the catalogue.
#[test]
fn user_blend_node_group_material_renders() {
    let Some(blender) = blender_or_skip("user_blend_node_group_material_renders") else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let script = dir.path().join("make.py");
    std::fs::write(&script, MAKE_BLEND).unwrap();
    let blend = dir.path().join("Checker Pack.blend");
    let out = Command::new(&blender)
        .args([
            "-b",
            "--factory-startup",
            "--python-exit-code",
            "1",
            "--python",
        ])
        .arg(&script)
        .arg("--")
        .arg(&blend)
        .output()
        .unwrap();
    assert!(out.status.success() && blend.is_file(), "{}", text(&out));
    let d = dir.path().to_str().unwrap();
    let list = run(&["materials", "list", "--materials", d]);
    let listed = String::from_utf8_lossy(&list.stdout);
    assert!(
        listed
            .lines()
            .any(|l| l.starts_with("checker_pack ") && l.contains(" user ")),
        "{}",
        text(&list)
    );
    let out = run(&[
        "materials",
        "check",
        "--materials",
        d,
        "--names",
        "checker_pack",
    ]);
    assert!(out.status.success(), "{}", text(&out));
    assert!(
        String::from_utf8_lossy(&out.stdout).contains("ok     checker_pack"),
        "{}",
        text(&out)
    );
}

/// `clevrtex materials sheet` of three materials into `dir/sheet.png` (cells cached in
/// `dir/cache`) with the Blender `blender`.
fn sheet_with(blender: &Path, dir: &Path, extra: &[&str]) -> std::process::Output {
    clevrtex()
        .env_remove("FAKE_BLENDER_MODE")
        .args([
            "materials",
            "sheet",
            "--names",
            "bricks,plain,moss",
            "--out",
        ])
        .arg(dir.join("sheet.png"))
        .arg("--cache")
        .arg(dir.join("cache"))
        .arg("--blender")
        .arg(blender)
        .args(extra)
        .output()
        .expect("run clevrtex")
}

/// The material renders are requests of the worker protocol, with `generate`'s failure
/// policy: a Blender killed mid-render is restarted, the material rendered again, and the
/// sheet still made.
#[test]
fn materials_sheet_survives_a_crashed_worker() {
    let dir = tempfile::tempdir().unwrap();
    let fake = format!(
        "env FAKE_BLENDER_MODE=material '{}'",
        fake_blender().display()
    );
    let blender = crash_once_then(dir.path(), &fake);
    let out = sheet_with(&blender, dir.path(), &[]);
    let t = text(&out);
    assert_eq!(out.status.code(), Some(0), "{t}");
    assert_eq!(t.matches("restarting a Blender worker").count(), 1, "{t}");
    assert!(
        t.contains("while rendering material `bricks` (sheet)"),
        "{t}"
    );
    assert!(t.contains("SIGSEGV"), "{t}");
    assert!(t.contains("segmentation fault while rendering"), "{t}");
    // Three 8x6 cells of the fake, in one row.
    let sheet = clevrtex_render::post::decode_png(&dir.path().join("sheet.png")).unwrap();
    assert_eq!((sheet.width, sheet.height), (24, 6), "{t}");
    let cached: Vec<_> = std::fs::read_dir(dir.path().join("cache"))
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    assert_eq!(cached.len(), 3, "{cached:?}");
    assert!(cached.iter().all(|f| f.ends_with(".png")), "{cached:?}");
}

/// A Blender that dies on every request: `--retries` restarts, then a clear error (which
/// material, the crash, Blender's last words, a hint), exit 1, and no sheet or stray files.
#[test]
fn materials_sheet_gives_up_on_a_worker_that_keeps_crashing() {
    let dir = tempfile::tempdir().unwrap();
    let blender = blender_wrapper(
        dir.path(),
        &format!(
            "FAKE_BLENDER_MODE=crash exec '{}' \"$@\"",
            fake_blender().display()
        ),
    );
    let out = sheet_with(&blender, dir.path(), &["--retries", "1"]);
    let t = text(&out);
    assert_eq!(out.status.code(), Some(1), "{t}");
    assert_eq!(t.matches("restarting a Blender worker").count(), 1, "{t}");
    assert!(t.contains("error: blender worker"), "{t}");
    assert!(
        t.contains("while rendering material `bricks` (sheet)"),
        "{t}"
    );
    assert!(t.contains("SIGSEGV"), "{t}");
    assert!(t.contains("--- stderr"), "{t}");
    assert!(t.contains("segmentation fault while rendering"), "{t}");
    assert!(t.contains("hint: "), "{t}");
    assert!(!dir.path().join("sheet.png").exists(), "{t}");
    let cache: Vec<_> = std::fs::read_dir(dir.path().join("cache"))
        .unwrap()
        .collect();
    assert!(cache.is_empty(), "{cache:?}");
}

/// A hung Blender is killed at the `--timeout` limit, as in `generate`.
#[test]
fn materials_check_kills_a_hung_worker_at_the_time_limit() {
    let dir = tempfile::tempdir().unwrap();
    let blender = blender_wrapper(
        dir.path(),
        &format!(
            "FAKE_BLENDER_MODE=hang exec '{}' \"$@\"",
            fake_blender().display()
        ),
    );
    let started = std::time::Instant::now();
    let out = clevrtex()
        .args(["materials", "check", "--names", "plain"])
        .args(["--timeout", "1", "--retries", "0", "--blender"])
        .arg(&blender)
        .output()
        .unwrap();
    let t = text(&out);
    assert_eq!(out.status.code(), Some(1), "{t}");
    assert!(
        t.contains("timed out after") && t.contains("rendering material `plain` (check)"),
        "{t}"
    );
    assert!(t.contains("it was killed"), "{t}");
    assert!(started.elapsed() < Duration::from_secs(30), "{t}");
}

/// Ctrl-C stops the Blender worker at once: exit code 130, the worker process gone.
#[test]
fn materials_sheet_stops_blender_on_ctrl_c() {
    let dir = tempfile::tempdir().unwrap();
    let pid_file = dir.path().join("worker.pid");
    // The wrapper records the worker's pid (kept by `exec`) once it is running.
    let blender = blender_wrapper(
        dir.path(),
        &format!(
            "echo $$ > '{}.tmp' && mv '{0}.tmp' '{0}'\nFAKE_BLENDER_MODE=hang exec '{}' \"$@\"",
            pid_file.display(),
            fake_blender().display()
        ),
    );
    let child = clevrtex()
        .args(["materials", "sheet", "--names", "plain", "--out"])
        .arg(dir.path().join("sheet.png"))
        .arg("--cache")
        .arg(dir.path().join("cache"))
        .arg("--blender")
        .arg(&blender)
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    let deadline = std::time::Instant::now() + Duration::from_secs(30);
    while !pid_file.exists() && std::time::Instant::now() < deadline {
        std::thread::sleep(Duration::from_millis(20));
    }
    let worker_pid = std::fs::read_to_string(&pid_file).expect("the worker never started");
    // Let the fake answer `ready` and receive its request.
    std::thread::sleep(Duration::from_millis(500));
    let sent = Command::new("kill")
        .args(["-INT", &child.id().to_string()])
        .status()
        .unwrap();
    assert!(sent.success());
    let out = child.wait_with_output().unwrap();
    let t = text(&out);
    assert_eq!(out.status.code(), Some(130), "{t}");
    assert!(t.contains("interrupted"), "{t}");
    assert!(!dir.path().join("sheet.png").exists(), "{t}");
    let alive = Command::new("kill")
        .args(["-0", worker_pid.trim()])
        .output()
        .unwrap();
    assert!(
        !alive.status.success(),
        "worker {worker_pid} still runs\n{t}"
    );
}

/// A random-bytes `x.blend` in a material directory is refused by name, not listed as a
/// material; a `--size 0` sheet is refused instead of writing a 4x4 image.
#[test]
fn a_fake_blend_and_a_zero_size_are_refused() {
    let dir = tempfile::tempdir().unwrap();
    std::fs::write(
        dir.path().join("x.blend"),
        b"\x00\x13random bytes, not Blender",
    )
    .unwrap();
    let d = dir.path().to_str().unwrap();
    let out = run(&["materials", "list", "--materials", d]);
    let t = text(&out);
    assert_eq!(out.status.code(), Some(1), "{t}");
    assert!(
        t.contains("x.blend") && t.contains("not a Blender file"),
        "{t}"
    );
    assert!(!t.contains("user node group"), "{t}");

    let sheet = dir.path().join("sheet.png");
    let out = run(&[
        "materials",
        "sheet",
        "--names",
        "plain",
        "--size",
        "0",
        "--out",
        sheet.to_str().unwrap(),
    ]);
    let t = text(&out);
    assert_eq!(out.status.code(), Some(2), "{t}");
    assert!(t.contains("0 is not in 16..=4096"), "{t}");
    assert!(!sheet.exists());
}

/// `materials stats` with nothing to compare (no user materials, or only `metal`) is an error
/// naming what was asked, before Blender starts (it panicked on an empty list).
#[test]
fn materials_stats_with_nothing_to_compare_is_refused() {
    for (args, names) in [
        (&["--set", "user"][..], "set `user`"),
        (&["--names", "metal"][..], "`--names`"),
    ] {
        let mut all = vec!["materials", "stats"];
        all.extend(args);
        let out = run(&all);
        let t = text(&out);
        assert_eq!(out.status.code(), Some(1), "{t}");
        assert!(
            t.contains(&format!("no materials to compare in {names}")) && t.contains("hint:"),
            "{t}"
        );
        assert!(!t.contains("panicked"), "{t}");
    }
}

/// The albedo pass is the material's base colour: `metal` objects of a `clevr` scene show
/// their CLEVR colour (Cycles' diffuse colour, the pass before issue 23, was near black on
/// them: 5-8 of 255), and `materials measure` reads the dataset (a rendered one, end to end).
/// Two scenes in one worker: the albedo AOV is removed for the second scene's visibility
/// render and added again for its final render (3.4 has no `aovs.remove`).
#[test]
fn albedo_pass_is_the_base_colour_metals_included() {
    let Some(blender) = blender_or_skip("albedo_pass_is_the_base_colour_metals_included") else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("out");
    let o = run(&[
        "generate",
        "--variant",
        "clevr",
        "-n",
        "2",
        "--seed",
        "2",
        "--width",
        "160",
        "--height",
        "120",
        "--samples",
        "4",
        "--passes",
        "rgb,mask,albedo",
        "--workers",
        "1",
        "--out",
        out.to_str().unwrap(),
        "--blender",
        blender.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", text(&o));
    let sub = out.join("clevrtex_clevr/0");
    let meta: serde_json::Value =
        serde_json::from_slice(&std::fs::read(sub.join("CLEVRTEX_clevr_000000.json")).unwrap())
            .unwrap();
    let mask =
        clevrtex_render::post::decode_png(&sub.join("CLEVRTEX_clevr_000000_flat.png")).unwrap();
    let albedo =
        clevrtex_render::post::decode_png(&sub.join("CLEVRTEX_clevr_000000_albedo_0001.png"))
            .unwrap();
    let mut metals = 0;
    for (i, obj) in meta["objects"].as_array().unwrap().iter().enumerate() {
        if obj["material"] != "metal" {
            continue;
        }
        let (mut sum, mut n) = ([0.0f64; 3], 0.0);
        for (p, &id) in mask.data.iter().enumerate() {
            if usize::from(id) == i + 1 {
                (0..3).for_each(|k| sum[k] += f64::from(albedo.data[3 * p + k]));
                n += 1.0;
            }
        }
        if n < 20.0 {
            continue;
        }
        let brightest = sum.iter().map(|s| s / n).fold(0.0, f64::max);
        assert!(
            brightest > 60.0,
            "metal object {} ({}) albedo {brightest}",
            i + 1,
            obj["color"]
        );
        metals += 1;
    }
    assert!(metals > 0, "the scene has no visible metal object: {meta}");
    let m = run(&["materials", "measure", out.to_str().unwrap()]);
    assert!(m.status.success(), "{}", text(&m));
    let stdout = String::from_utf8_lossy(&m.stdout);
    assert!(
        stdout.contains("clevr ") && stdout.contains("metal"),
        "{stdout}"
    );
}
