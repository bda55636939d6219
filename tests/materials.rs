//! Integration tests for `clevrtex materials`.

use std::path::Path;
use std::process::Command;

use crate::util::{blender_or_skip, repo_root, run, text};

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
    let mjson = dir.path().join("materials.json");
    std::fs::write(&mjson, &json.stdout).unwrap();
    let out = Command::new(blender)
        .args([
            "-b",
            "--factory-startup",
            "--python-exit-code",
            "1",
            "--python",
        ])
        .arg(repo_root().join("blender_scripts/material_tool.py"))
        .arg("--")
        .args([
            "--mode",
            "density",
            "--names",
            "stripes,bricks",
            "--size",
            "400",
        ])
        .args(["--samples", "4", "--tag", "@@T@@", "--materials"])
        .arg(&mjson)
        .arg("--out-dir")
        .arg(dir.path().join("out"))
        .output()
        .unwrap();
    assert!(out.status.success(), "{}", text(&out));
    let stdout = String::from_utf8_lossy(&out.stdout);
    let replies: Vec<serde_json::Value> = stdout
        .lines()
        .filter_map(|l| l.strip_prefix("@@T@@ "))
        .map(|l| serde_json::from_str(l).unwrap())
        .collect();
    assert_eq!(replies.len(), 2, "{stdout}");
    let stripes = &replies[0];
    let (small, large) = (
        stripes["period_small"].as_f64().unwrap(),
        stripes["period_large"].as_f64().unwrap(),
    );
    eprintln!("stripe period: small cube {small:.4}, large cube {large:.4} (world units)");
    assert!((small - 0.1).abs() < 0.01, "{stripes}");
    assert!((large - 0.1).abs() < 0.01, "{stripes}");
    // The large cube shows about twice as many stripes as the small one.
    let flips = |k: &str| stripes[k].as_f64().unwrap();
    let ratio = flips("flips_large") / flips("flips_small");
    assert!((1.7..2.4).contains(&ratio), "{stripes}");
    // Bricks: the mortar-line period along x agrees between sizes too.
    let b = &replies[1];
    let (bs, bl) = (
        b["period_small"].as_f64().unwrap(),
        b["period_large"].as_f64().unwrap(),
    );
    assert!((bs / bl - 1.0).abs() < 0.3, "{b}");
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
