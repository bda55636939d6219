//! Issue 49: every reader of one dataset gives the same numbers. A dataset of two variants
//! rendered here with the real Blender (every pass), read by the Python `Dataset` and by the
//! real `webdataset`, Hugging Face `datasets` and pycocotools over the exports of this build:
//! one decode per pass, the metadata's floats bit for bit, one id table, COCO files of both
//! variants that merge (`tests/export_pipelines/readers_agree.py`).

use crate::util::{blender_or_skip, clevrtex, repo_root, test_python_or_skip, text};

#[test]
fn every_reader_gives_the_same_passes_floats_and_ids() {
    let test = "every_reader_gives_the_same_passes_floats_and_ids";
    let Some(python) =
        test_python_or_skip(test, "clevrtex, webdataset, datasets, pycocotools, numpy")
    else {
        return;
    };
    let Some(blender) = blender_or_skip(test) else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let data = dir.path().join("data");
    for (variant, seed) in [("clevr", "3"), ("full", "4")] {
        let o = clevrtex()
            .args(["generate", "--variant", variant, "-n", "6", "--seed", seed])
            // 4 samples: a pixel on an edge averages normals, so the PNG holds means shorter
            // than 1 there, which every reader must decode alike.
            .args(["--width", "40", "--height", "30", "--samples", "4"])
            .args([
                "--passes",
                "rgb,mask,depth,normal,albedo,shadow",
                "--blender",
            ])
            .arg(&blender)
            .arg("--out")
            .arg(&data)
            .output()
            .unwrap();
        assert_eq!(o.status.code(), Some(0), "{variant}: {}", text(&o));
    }
    assert!(
        short_normals(&data) > 100,
        "the renders have no edge pixels whose mean normal is short: the test would not see a reader that skips the decode"
    );
    let out = |name: &str| dir.path().join(name);
    for (name, extra) in [
        ("wds", &["--objects", "10"][..]),
        ("wds-crop", &["--objects", "10", "--crop"]),
        ("wds-16", &["--objects", "10", "--crop", "--resize", "16"]),
        ("coco", &["--format", "coco"]),
    ] {
        let o = clevrtex()
            .arg("export")
            .args(extra)
            .arg(&data)
            .arg(out(name))
            .output()
            .unwrap();
        assert_eq!(o.status.code(), Some(0), "{name}: {}", text(&o));
    }
    let ids: serde_json::Value =
        serde_json::from_slice(&std::fs::read(out("coco").join("ids.json")).unwrap()).unwrap();
    assert_eq!(ids["coco"]["variant_numbers"]["full"], 1, "{ids}");
    assert_eq!(ids["coco"]["variant_numbers"]["clevr"], 7, "{ids}");
    assert_eq!(ids["names"]["shape"][0], "cube", "{ids}");
    let o = std::process::Command::new(&python)
        .arg(repo_root().join("tests/export_pipelines/readers_agree.py"))
        .args([&data, &out("wds"), &out("wds-crop"), &out("wds-16")])
        .arg("16")
        .arg(out("coco"))
        .arg("10")
        .env("HF_HOME", dir.path().join("hf"))
        .env("HF_DATASETS_OFFLINE", "1")
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", text(&o));
    let stdout = String::from_utf8_lossy(&o.stdout);
    let line = stdout.lines().last().unwrap_or_default();
    // 12 samples read from each of the three shard sets; every object's 7 numbers, the
    // camera's 25, and COCO's 7 per visible object, compared bit for bit.
    let field = |key: &str| -> u64 {
        line.split(&format!("{key}: "))
            .nth(1)
            .and_then(|r| r.split_whitespace().next())
            .and_then(|n| n.parse().ok())
            .unwrap_or_else(|| panic!("no `{key}` in {line:?}\n{}", text(&o)))
    };
    assert!(line.starts_with("variants: clevr full "), "{line}");
    assert_eq!(field("samples"), 36, "{line}");
    assert_eq!(field("coco"), 12, "{line}");
    let objects = field("objects");
    assert!(objects >= 36, "{line}");
    assert!(field("floats") >= objects * 7 + 12 * 25, "{line}");
}

/// Pixels of the dataset's normal PNGs (not background) whose stored mean normal is shorter
/// than 0.99: where a reader's decode (the unit vector) and the raw mean differ.
fn short_normals(data: &std::path::Path) -> usize {
    let mut n = 0;
    for variant in std::fs::read_dir(data).unwrap().flatten() {
        let Ok(sub) = std::fs::read_dir(variant.path().join("0")) else {
            continue;
        };
        for f in sub.flatten() {
            if !f
                .file_name()
                .to_string_lossy()
                .ends_with("_normal_0001.png")
            {
                continue;
            }
            let img = image::open(f.path()).unwrap().into_rgb16();
            n += img
                .pixels()
                .filter(|p| p.0 != [32768; 3])
                .map(|p| p.0.map(|c| f64::from(c) / 65535.0 * 2.0 - 1.0))
                .filter(|v| (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt() < 0.99)
                .count();
        }
    }
    n
}
