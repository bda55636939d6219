//! One scene, two Blenders: Debian's 3.4.1 and PyPI's `bpy` 4.5 render the same scene files
//! alike (`blender_scripts/compat.py` holds every version difference). Needs both; required
//! under `CLEVRTEX_REQUIRE_TOOLS=1` plus `CLEVRTEX_REQUIRE_BPY=1` (what `.ci/run` sets).
//!
//! What "alike" means, and the tolerances (measured, see `docs/notes/scene-format.md`,
//! "Across Blender versions"):
//! - masks: identical ids on every pixel;
//! - depth: within 1 mm on every pixel, except on a truly displaced backdrop (there the two
//!   versions dice and sample the relief's steep edges differently: measured on `full` image 0
//!   of seed 0, bricks: median 1 mm, mean signed 0.1 mm, up to 72 mm at brick edges);
//! - mean colour of the RGB: each channel's mean within [`MEAN_RGB_TOLERANCE`] of 255 levels
//!   (4.0's Principled BSDF conserves energy between its specular and diffuse layers, so the
//!   same material is a little darker; measured 4-10 levels at 160x120, 32 spp), over the
//!   whole image and over the objects' pixels; a truly displaced backdrop included since issue
//!   50 (`compat.true_displacement_method`; before, `forest_ground_twigs` displaced was ~27
//!   levels darker on 4.5);
//! - a material as the displaced backdrop or on the objects (`clevrtex materials parity`): mean
//!   linear luminance within 3%, mean depth within 1%.

use std::path::Path;

use clevrtex_render::post::decode_png;
use clevrtex_scene::SceneFile;

use crate::util::{blender_or_skip, bpy_or_skip, clevrtex, repo_root, text};

/// Largest mean absolute depth difference on a truly displaced backdrop, mm.
const MEAN_ABS_DISPLACED_DEPTH_MM: f64 = 20.0;

/// Largest difference of a channel's mean (0..255) between 3.4 and 4.5 on one image.
const MEAN_RGB_TOLERANCE: f64 = 14.0;

fn scenes(dir: &Path) -> Vec<SceneFile> {
    let config = clevrtex_scene::Config::builtin("full").unwrap();
    let mut out = Vec::new();
    for index in 0..3 {
        let mut scene = clevrtex_scene::sample(
            &config,
            &clevrtex_scene::SampleRequest {
                seed: 0,
                index,
                attempt: 0,
                total: 3,
            },
        )
        .unwrap();
        scene.render.width = 96;
        scene.render.height = 72;
        scene.render.samples = 16;
        std::fs::write(
            dir.join(format!("{}.json", scene.stem)),
            serde_json::to_string(&scene).unwrap(),
        )
        .unwrap();
        out.push(scene);
    }
    out
}

fn render(blender: &Path, scenes: &Path, out: &Path) {
    let run = clevrtex()
        .args(["render", "--workers", "1", "--blender"])
        .arg(blender)
        .arg("--out")
        .arg(out)
        .arg(scenes)
        .output()
        .unwrap();
    let t = text(&run);
    assert_eq!(run.status.code(), Some(0), "{}: {t}", blender.display());
}

/// Mean of each channel of the RGB image at `path` over the pixels `keep` takes (by index).
fn mean_rgb(path: &Path, keep: impl Fn(usize) -> bool) -> [f64; 3] {
    let png = decode_png(path).unwrap();
    assert_eq!(png.channels, 3);
    let (mut sum, mut n) = ([0.0; 3], 0usize);
    for (_, px) in png.data.chunks(3).enumerate().filter(|(i, _)| keep(*i)) {
        for c in 0..3 {
            sum[c] += px[c] as f64;
        }
        n += 1;
    }
    assert!(n > 0, "{}: no pixel to average", path.display());
    sum.map(|s| s / n as f64)
}

#[test]
fn blender_3_4_and_bpy_4_5_render_a_scene_alike() {
    let test = "blender_3_4_and_bpy_4_5_render_a_scene_alike";
    let (Some(blender), Some(bpy)) = (blender_or_skip(test), bpy_or_skip(test)) else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let scene_dir = dir.path().join("scenes");
    std::fs::create_dir_all(&scene_dir).unwrap();
    let scenes = scenes(&scene_dir);
    let (a, b) = (dir.path().join("a"), dir.path().join("b"));
    render(&blender, &scene_dir, &a);
    render(&bpy, &scene_dir, &b);
    let sub = |root: &Path, stem: &str, suffix: &str| {
        root.join(format!("clevrtex_full/0/{stem}{suffix}"))
    };
    for scene in &scenes {
        let stem = &scene.stem;
        let meta_b: serde_json::Value =
            serde_json::from_slice(&std::fs::read(sub(&b, stem, ".json")).unwrap()).unwrap();
        let version = meta_b["blender_version"].as_str().unwrap_or("");
        assert!(
            version.starts_with('4') || version.starts_with('5'),
            "{version}"
        );
        // Which parity settings made the sample (compat.parity_settings): every switch on for
        // 4.x and 5.x, none on 3.4.
        for switch in [
            "coat",
            "sheen",
            "ggx",
            "ior",
            "layers",
            "fresnel",
            "coat_gtr1",
            "disney_diffuse",
            "metal_fresnel",
            "coat_mis",
        ] {
            assert_eq!(
                meta_b["blender_compat"][switch],
                serde_json::json!(true),
                "{stem}: {version} metadata lacks compat switch `{switch}`: {}",
                meta_b["blender_compat"]
            );
        }
        let meta_a: serde_json::Value =
            serde_json::from_slice(&std::fs::read(sub(&a, stem, ".json")).unwrap()).unwrap();
        assert!(
            meta_a.get("blender_compat").is_none(),
            "{stem}: 3.4 needs no parity settings, got {}",
            meta_a["blender_compat"]
        );

        let ma = decode_png(&sub(&a, stem, "_flat.png")).unwrap();
        let mb = decode_png(&sub(&b, stem, "_flat.png")).unwrap();
        let differing = ma.data.iter().zip(&mb.data).filter(|(x, y)| x != y).count();
        assert_eq!(differing, 0, "{stem}: {differing} mask pixels differ");
        assert!(ma.data.iter().any(|&v| v > 0), "{stem}: no object visible");

        let da = decode_png(&sub(&a, stem, "_depth_0001.png")).unwrap();
        let db = decode_png(&sub(&b, stem, "_depth_0001.png")).unwrap();
        let displaced_backdrop = scene.backdrop.material.displacement.unwrap_or(0.0) > 0.0;
        // On a displaced backdrop: the mean signed and mean absolute difference.
        let (mut signed, mut abs, mut backdrop) = (0.0f64, 0.0f64, 0usize);
        for (i, (&x, &y)) in da.data.iter().zip(&db.data).enumerate() {
            let d = x as f64 - y as f64; // units of 1 mm
            if displaced_backdrop && ma.data[i] == 0 {
                if x != u16::MAX && y != u16::MAX {
                    signed += d;
                    abs += d.abs();
                    backdrop += 1;
                }
            } else {
                assert!(d.abs() <= 1.0, "{stem}: depth {x} vs {y} mm at pixel {i}");
            }
        }
        if backdrop > 0 {
            let (signed, abs) = (signed / backdrop as f64, abs / backdrop as f64);
            eprintln!("{stem}: displaced backdrop depth: mean signed {signed:.2} mm, mean |d| {abs:.2} mm");
            assert!(
                signed.abs() <= 1.0 && abs <= MEAN_ABS_DISPLACED_DEPTH_MM,
                "{stem}: displaced backdrop depth differs by {signed:.2} mm on average ({abs:.2} mm absolute)"
            );
        }

        // The whole image, a displaced backdrop included (issue 50: before
        // `compat.true_displacement_method`, `forest_ground_twigs` displaced was ~27 levels
        // darker on 4.5); the objects' pixels on their own too.
        for (what, keep) in [
            (
                "whole image",
                Box::new(|_: usize| true) as Box<dyn Fn(usize) -> bool>,
            ),
            ("objects", Box::new(|i: usize| ma.data[i] > 0)),
        ] {
            let (ra, rb) = (
                mean_rgb(&sub(&a, stem, ".png"), &keep),
                mean_rgb(&sub(&b, stem, ".png"), &keep),
            );
            eprintln!("{stem}: mean RGB of the {what}: 3.4 {ra:.1?} vs {version} {rb:.1?}");
            for c in 0..3 {
                assert!(
                    (ra[c] - rb[c]).abs() <= MEAN_RGB_TOLERANCE,
                    "{stem}: mean RGB of the {what} {ra:?} (3.4) vs {rb:?} ({version})"
                );
            }
        }
    }
}

/// OIDN (`render.denoise`, an opt-in lever of bpy 4.5) changes the RGB only: the mask, depth,
/// normal and albedo passes are byte-identical to those of the same scene without it.
#[test]
fn denoising_changes_the_rgb_only() {
    let Some(bpy) = bpy_or_skip("denoising_changes_the_rgb_only") else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let config = clevrtex_scene::Config::builtin("full").unwrap();
    let mut scene = clevrtex_scene::sample(
        &config,
        &clevrtex_scene::SampleRequest {
            seed: 0,
            index: 1,
            attempt: 0,
            total: 2,
        },
    )
    .unwrap();
    scene.render.width = 64;
    scene.render.height = 48;
    scene.render.samples = 4;
    let stem = scene.stem.clone();
    let mut outputs = Vec::new();
    for denoise in [false, true] {
        let scenes = dir.path().join(format!("scenes-{denoise}"));
        std::fs::create_dir_all(&scenes).unwrap();
        scene.render.denoise = denoise;
        std::fs::write(
            scenes.join(format!("{stem}.json")),
            serde_json::to_string(&scene).unwrap(),
        )
        .unwrap();
        let out = dir.path().join(format!("out-{denoise}"));
        render(&bpy, &scenes, &out);
        outputs.push(out.join("clevrtex_full/0"));
    }
    let read = |i: usize, suffix: &str| std::fs::read(outputs[i].join(format!("{stem}{suffix}")));
    for suffix in [
        "_flat.png",
        "_depth_0001.png",
        "_normal_0001.png",
        "_albedo_0001.png",
    ] {
        assert!(
            read(0, suffix).unwrap() == read(1, suffix).unwrap(),
            "{suffix} differs with denoising"
        );
    }
    assert_ne!(
        read(0, ".png").unwrap(),
        read(1, ".png").unwrap(),
        "denoising left the RGB unchanged: was OIDN applied?"
    );
}

/// Denoising where a scene asks for it (`render.denoise`, the `fast` preset) runs OIDN on the
/// worker's own device (issue 40): on a GPU worker (`compat.DEVICE` set from `--device CUDA:0`)
/// on the GPU, on a CPU worker on the CPU. Checked on
/// the settings the bridge makes (no GPU is needed to set them), on every Blender that has
/// OIDN's GPU switch (`denoising_use_gpu`, 4.1+; 3.4 has neither it nor OIDN).
#[test]
fn denoising_runs_on_the_workers_own_device() {
    for blender in crate::util::test_blenders("denoising_runs_on_the_workers_own_device") {
        let dir = tempfile::tempdir().unwrap();
        let script = dir.path().join("denoise.py");
        std::fs::write(
            &script,
            format!(
                r#"import sys
sys.path.insert(0, {root:?})
import bpy, compat
c = bpy.context.scene.cycles
if not (compat.features()["oidn"] and hasattr(c, "denoising_use_gpu")):
    print("NO-OIDN-GPU-SWITCH")
    sys.exit(0)
for device, gpu in ((("CPU", 0), False), (("CUDA", 0), True), (("OPTIX", 1), True)):
    compat.DEVICE = device
    c.use_denoising = False
    compat.apply_levers(c, {{"denoise": True}})
    assert c.use_denoising and c.denoiser == "OPENIMAGEDENOISE", device
    assert c.denoising_use_gpu == gpu, (device, c.denoising_use_gpu)
print("DENOISE-DEVICE-OK")
"#,
                root = repo_root().join("blender_scripts").to_string_lossy()
            ),
        )
        .unwrap();
        let flavour = clevrtex_render::blender::flavour(&blender);
        let out = clevrtex_render::blender::worker_command(&blender, flavour, &script, &[])
            .output()
            .unwrap();
        let t = text(&out);
        assert!(out.status.success(), "{}: {t}", blender.display());
        // PyPI's bpy (4.5) has OIDN and the switch; Debian's 3.4.1 has no OIDN.
        if flavour == clevrtex_render::blender::Flavour::PythonModule {
            assert!(t.contains("DENOISE-DEVICE-OK"), "{t}");
        } else {
            assert!(
                t.contains("DENOISE-DEVICE-OK") || t.contains("NO-OIDN-GPU-SWITCH"),
                "{t}"
            );
        }
    }
}

/// `compat.coat_gtr1_lobes` (the `coat_gtr1` parity switch): three GGX lobes whose weights sum
/// to 1 and whose energy within each half-vector cone follows 3.4's GTR1 clearcoat closely,
/// for the recipes' coat roughnesses; a mirror and a flat coat keep one lobe. And
/// `compat.coat_v1_lobes` (`coat_mis`): a sharp coat adds a GGX lobe and its sum is ~1.6x the
/// coat's energy, a rough one is GTR1's lobes alone. The fit is pure Python, run in Blender
/// 3.4 (the module imports `bpy`).
#[test]
fn coat_gtr1_lobes_fit_the_gtr1_clearcoat() {
    let Some(blender) = blender_or_skip("coat_gtr1_lobes_fit_the_gtr1_clearcoat") else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let script = dir.path().join("fit.py");
    std::fs::write(
        &script,
        format!(
            r#"import math, sys
sys.path.insert(0, {root:?})
import compat
for r in (0.05, 0.15, 0.3):
    lobes = compat.coat_gtr1_lobes(r)
    assert len(lobes) == 3, lobes
    ws = [w for _, w in lobes]
    assert abs(sum(ws) - 1.0) < 1e-9 and min(ws) >= 0.0, lobes
    a2 = r ** 4
    lo, hi = math.log(a2 * 1e-2), math.log(1e3)
    worst = 0.0
    for i in range(60):
        s = math.exp(lo + (hi - lo) * i / 59)
        gtr1 = math.log((a2 + s) / (a2 * (1 + s))) / -math.log(a2)
        mix = sum(w * s / (lr ** 4 + s) for lr, w in lobes)
        worst = max(worst, abs(mix - gtr1))
    assert worst < 0.03, (r, worst)
    print("fit", r, round(worst, 4))
# coat_mis: 3.4's sharp coat shows GGX's peak and GTR1's tails, more than the coat's energy;
# a rough one GTR1 alone, so the lobes are coat_gtr1's.
eg, et = compat.coat_mis_shares(0.05)
assert 0.9 < eg < 1.0 and 0.55 < et < 0.8 and 1.5 < eg + et < 1.75, (eg, et)
lobes = compat.coat_v1_lobes(0.05)
assert lobes[0] == (0.05, eg) and len(lobes) == 4, lobes
assert abs(sum(w for _, w in lobes[1:]) - et) < 1e-9, lobes
eg, et = compat.coat_mis_shares(0.3)
assert eg < 0.01 and et > 0.99, (eg, et)
assert [r for r, _ in compat.coat_v1_lobes(0.3)] == [r for r, _ in compat.coat_gtr1_lobes(0.3)]
print("MIS", compat.coat_mis_shares(0.05), compat.coat_mis_shares(0.15))
assert compat.coat_gtr1_lobes(0.0) == [(0.0, 1.0)], compat.coat_gtr1_lobes(0.0)
assert compat.coat_gtr1_lobes(1.0) == [(1.0, 1.0)], compat.coat_gtr1_lobes(1.0)
print("FIT-OK")
"#,
            root = repo_root().join("blender_scripts").to_string_lossy()
        ),
    )
    .unwrap();
    // Started as the bridge is (the script ignores the bridge's arguments).
    let flavour = clevrtex_render::blender::flavour(&blender);
    let out = clevrtex_render::blender::worker_command(&blender, flavour, &script, &[])
        .output()
        .unwrap();
    let t = text(&out);
    assert!(out.status.success() && t.contains("FIT-OK"), "{t}");
}

/// v1's Fresnel of a metal at 60 degrees of incidence (Cycles 3.x `interpolate_fresnel_color`):
/// from colour `c` to white by the dielectric Fresnel of IOR 1.5 normalised to 0 at normal
/// incidence.
fn v1_metal_fresnel(c: f64, cos: f64) -> f64 {
    let dielectric = |cos: f64| {
        let eta: f64 = 1.5;
        let g = (eta * eta - 1.0 + cos * cos).sqrt();
        let a = (g - cos) / (g + cos);
        let b = (cos * (g + cos) - 1.0) / (cos * (g - cos) + 1.0);
        0.5 * a * a * (1.0 + b * b)
    };
    let f0 = dielectric(1.0);
    let fh = (dielectric(cos) - f0) / (1.0 - f0);
    c + (1.0 - c) * fh
}

/// Each case of `cases` (JSON values of `blender_scripts/dev/area_light_probe.py`) rendered by
/// `program` (started as the bridge is), in `dir`: the mean Combined pass by case name.
fn area_light_means(
    program: &Path,
    cases: &[serde_json::Value],
    dir: &Path,
) -> std::collections::HashMap<String, f64> {
    let stem = program.to_string_lossy().replace('/', "_");
    let cases_path = dir.join(format!("cases{stem}.json"));
    let out_path = dir.join(format!("out{stem}.jsonl"));
    std::fs::write(&cases_path, serde_json::to_string(cases).unwrap()).unwrap();
    let script = repo_root().join("blender_scripts/dev/area_light_probe.py");
    let flavour = clevrtex_render::blender::flavour(program);
    let args = [
        cases_path.into_os_string(),
        out_path.clone().into_os_string(),
    ];
    let out = clevrtex_render::blender::worker_command(program, flavour, &script, &args)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}: {}",
        program.display(),
        text(&out)
    );
    let mut combined = std::collections::HashMap::new();
    for line in std::fs::read_to_string(&out_path).unwrap().lines() {
        let v: serde_json::Value = serde_json::from_str(line).unwrap();
        let name = v["case"]["name"].as_str().unwrap().to_string();
        combined.insert(name, v["means"]["Combined"].as_f64().unwrap());
    }
    combined
}

/// A metal reflects by v1's Fresnel on 4.x too (`compat_principled.PARITY["metal_fresnel"]`:
/// the metal made a dielectric lobe of tint colour / F0). One area light reflected by a
/// flat metal plane at 60 degrees of incidence (`blender_scripts/dev/area_light_probe.py`,
/// the whole reflection in view): on each Blender the dark metal's reflection over a white
/// metal's (the same paths, so noise cancels) is v1's Fresnel at that angle; 4.x's own metal
/// (the switch off: Schlick's curve, F82 tint white) is 6% under it, which the bounds catch.
#[test]
fn a_metal_reflects_by_v1s_fresnel_on_every_blender() {
    let test = "a_metal_reflects_by_v1s_fresnel_on_every_blender";
    let (Some(blender), Some(bpy)) = (blender_or_skip(test), bpy_or_skip(test)) else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let case = |name: &str, color: f64, off: &[&str]| {
        serde_json::json!({
            "name": name, "material": "principled",
            "inputs": {"Metallic": 1.0, "Base Color": [color, color, color, 1.0],
                       "Roughness": 0.2},
            "cam_elev": 30, "light_elev": 30, "view": 12, "samples": 256,
            "parity_off": off,
        })
    };
    let cases = [
        case("white", 1.0, &[]),
        case("dark", 0.2, &[]),
        case("dark_schlick", 0.2, &["metal_fresnel"]),
    ];
    let expected = v1_metal_fresnel(0.2, 60f64.to_radians().cos());
    let mut ratios = Vec::new();
    for program in [&blender, &bpy] {
        let combined = area_light_means(program, &cases, dir.path());
        let (white, dark) = (combined["white"], combined["dark"]);
        assert!(
            white > 0.01,
            "{}: no reflection seen: {combined:?}",
            program.display()
        );
        let ratio = dark / white;
        eprintln!(
            "{}: dark / white metal {ratio:.4}, v1's Fresnel at 60 degrees {expected:.4}, \
             4.x's own metal {:.4}",
            program.display(),
            combined["dark_schlick"] / white
        );
        assert!(
            (ratio / expected - 1.0).abs() < 0.015,
            "{}: a metal of colour 0.2 reflects {ratio:.4} of a white one at 60 degrees, \
             v1's Fresnel {expected:.4}: {combined:?}",
            program.display()
        );
        ratios.push((ratio, combined["dark_schlick"] / white));
    }
    // On 3.4 the switch is nothing; on 4.5 without it the metal is Schlick's, below the bounds
    // (the check above would catch it).
    assert!((ratios[0].1 / ratios[0].0 - 1.0).abs() < 1e-9, "{ratios:?}");
    assert!(ratios[1].1 / expected < 0.96, "{ratios:?}");
}

/// A sharp clearcoat reflects a light on 4.x as much as 3.4's does (`compat_principled.PARITY
/// ["coat_mis"]`): 3.4 samples its coat with GGX and weighs it with GTR1, and shows ~1.7x the
/// coat's energy. One area light reflected by a flat black plane with a coat of roughness 0.05
/// and nothing else (`blender_scripts/dev/area_light_probe.py`, the whole reflection in view),
/// at 60 and 30 degrees of elevation: 4.5 within 15% of 3.4 (measured 1.03 and 1.11); 4.x's
/// coat without the switch (GTR1's lobes, the coat's energy) is ~0.6 of 3.4's.
#[test]
fn a_sharp_clearcoat_reflects_a_light_as_on_3_4() {
    let test = "a_sharp_clearcoat_reflects_a_light_as_on_3_4";
    let (Some(blender), Some(bpy)) = (blender_or_skip(test), bpy_or_skip(test)) else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let mut cases = Vec::new();
    for elev in [60, 30] {
        for off in [false, true] {
            cases.push(serde_json::json!({
                "name": format!("coat{elev}{}", if off { "_off" } else { "" }),
                "material": "principled",
                "inputs": {"Base Color": [0.0, 0.0, 0.0, 1.0], "Specular": 0.0,
                           "Clearcoat": 1.0, "Clearcoat Roughness": 0.05},
                "cam_elev": elev, "light_elev": elev, "view": 12, "samples": 1024,
                "parity_off": if off { vec!["coat_mis"] } else { vec![] },
            }));
        }
    }
    let runs: Vec<_> = [&blender, &bpy]
        .into_iter()
        .map(|program| area_light_means(program, &cases, dir.path()))
        .collect();
    let (old, new) = (&runs[0], &runs[1]);
    for elev in [60, 30] {
        let key = format!("coat{elev}");
        assert!(old[&key] > 1e-4, "3.4 saw no reflection: {old:?}");
        let with = new[&key] / old[&key];
        let without = new[&format!("{key}_off")] / old[&key];
        eprintln!("coat at {elev} degrees, 4.5 / 3.4: {with:.3} (without coat_mis {without:.3})");
        assert!(
            (0.85..1.15).contains(&with),
            "{elev} degrees: 4.5's sharp coat reflects {with:.3} of 3.4's: {old:?} {new:?}"
        );
        assert!(
            without < 0.75,
            "{elev} degrees: without coat_mis {without:.3}"
        );
    }
}

/// The bridge lists the CUDA kernels each Blender's Cycles ships (`compat.cuda_kernels`, sent
/// in `ready` as `cuda_kernels`), from which `generate` and `doctor` tell whether a GPU's
/// kernel must first be compiled: Debian's 3.4 ships none; PyPI's bpy 4.5 ships cubins that
/// include sm_86 and sm_89 but not sm_80 or sm_90 (A100, H100), and PTX compute_75.
#[test]
fn bridge_lists_the_cuda_kernels_each_blender_ships() {
    use clevrtex_render::device::{CudaKernels, KernelLoad};
    for blender in crate::util::test_blenders("bridge_lists_the_cuda_kernels_each_blender_ships") {
        let dir = tempfile::tempdir().unwrap();
        let script = dir.path().join("kernels.py");
        std::fs::write(
            &script,
            format!(
                "import json, sys\nsys.path.insert(0, {root:?})\nimport bpy\nimport compat\nprint('KERNELS ' + json.dumps(compat.cuda_kernels()))\nprint('VERSION ' + bpy.app.version_string)\n",
                root = repo_root().join("blender_scripts").to_string_lossy()
            ),
        )
        .unwrap();
        // Started as the bridge is (the script ignores the bridge's arguments).
        let flavour = clevrtex_render::blender::flavour(&blender);
        let out = clevrtex_render::blender::worker_command(&blender, flavour, &script, &[])
            .output()
            .unwrap();
        let t = text(&out);
        assert!(out.status.success(), "{t}");
        let stdout = String::from_utf8_lossy(&out.stdout);
        let field = |key: &str| {
            stdout
                .lines()
                .find_map(|l| l.strip_prefix(key))
                .unwrap_or_else(|| panic!("no `{key}` line: {t}"))
                .to_string()
        };
        let kernels: CudaKernels = serde_json::from_str(&field("KERNELS ")).unwrap();
        let version = field("VERSION ");
        if version.starts_with("3.") {
            assert_eq!(kernels, CudaKernels::default(), "{version}: {t}");
        } else {
            for cc in [86, 89] {
                assert_eq!(
                    kernels.load_for(cc),
                    KernelLoad::Shipped,
                    "{version}: {kernels:?}"
                );
            }
            for cc in [80, 90] {
                assert_eq!(
                    kernels.load_for(cc),
                    KernelLoad::Compiled { from: 75 },
                    "{version}: {kernels:?}"
                );
            }
        }
    }
}

/// Materials whose displaced backdrop 4.5 rendered 12-27% darker than 3.4 before issue 50
/// (Cycles 4.x's bump derived from the displacement; `compat.true_displacement_method`), and
/// the rough brick 4.5 rendered 5.8% darker (v2's Lambert diffuse; `compat.disney_diffuse`).
const DISPLACED_PARITY_MATERIALS: &str =
    "jagged_cliff_rock,copper_chainmail,corrugated_iron,flemish_red_bricks";

/// Materials measured on the objects: a plain one, a displacing one with sheen, a rough one
/// 4.5 rendered 4.3% darker (`compat.disney_diffuse`) and a dark fabric with sheen it rendered
/// 13% brighter (the sheen factor of `compat_principled._PRINCIPLED_SCALE`).
const OBJECT_PARITY_MATERIALS: &str = "plain,moss,rubber,rhombus_carpet";

/// `clevrtex materials parity` on 3.4 and 4.5 (issue 50): the materials 4.5 rendered darkest
/// or brightest as backdrop and on the objects, each within 3% in mean linear luminance
/// and 1% in mean depth (the command's bounds); the table names both Blenders, and the
/// command refuses to run with one.
#[test]
fn materials_render_alike_on_3_4_and_bpy_4_5_by_materials_parity() {
    let test = "materials_render_alike_on_3_4_and_bpy_4_5_by_materials_parity";
    let (Some(blender), Some(bpy)) = (blender_or_skip(test), bpy_or_skip(test)) else {
        return;
    };
    let both = |role: &str, names: &str| {
        let out = clevrtex()
            .args(["materials", "parity", "--as", role, "--names", names])
            .args(["--size", "64", "--samples", "16", "--blender"])
            .arg(&blender)
            .arg("--blender")
            .arg(&bpy)
            .output()
            .unwrap();
        let t = text(&out);
        eprintln!("{t}");
        assert!(out.status.success(), "{role}: {t}");
        let stdout = String::from_utf8_lossy(&out.stdout).to_string();
        assert!(
            stdout.contains("| material | as | 3.4.1 luminance, depth m, albedo | 4.5."),
            "{stdout}"
        );
        for name in names.split(',') {
            assert!(
                stdout.contains(&format!("| `{name}` | {role} | ")),
                "{name}: {stdout}"
            );
        }
        assert!(!stdout.contains("**past**"), "{stdout}");
        assert!(
            t.contains("within the bounds (luminance 3%, depth 1%)"),
            "{t}"
        );
    };
    both("backdrop", DISPLACED_PARITY_MATERIALS);
    both("object", OBJECT_PARITY_MATERIALS);
    let one = clevrtex()
        .args(["materials", "parity", "--names", "plain", "--blender"])
        .arg(&blender)
        .output()
        .unwrap();
    let t = text(&one);
    assert_eq!(one.status.code(), Some(1), "{t}");
    assert!(
        t.contains("compares two or more Blenders, but has only `") && t.contains("hint:"),
        "{t}"
    );
}
