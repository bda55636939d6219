//! `clevrtex export --format webdataset`: shards read back by the real `webdataset` library
//! (in the test venv) equal the source files, split by split, in index order.

use crate::util::{blender_or_skip, clevrtex, test_python_or_skip, text};

/// Reads every shard of `index.json` with `webdataset` and checks each sample against the
/// dataset's own files (found through its metadata); prints `split keys...` per split.
const READ_BACK: &str = r#"
import json, os, sys
import webdataset as wds
out, src = sys.argv[1], sys.argv[2]
index = json.load(open(os.path.join(out, "index.json")))
seen = {}
for entry in index["shards"]:
    shard = entry["shard"]
    url = os.path.join(out, shard["file"])
    n = 0
    for sample in wds.WebDataset(url, shardshuffle=False):
        n += 1
        key = sample["__key__"]
        meta = json.loads(sample["json"])
        assert meta["stem"] == key, (key, meta["stem"])
        assert meta["split"] == entry["split"], (key, meta["split"], entry["split"])
        folder = os.path.join(src, "clevrtex_" + meta["variant"], str(meta["image_index"] // 1000))
        with open(os.path.join(folder, key + ".json"), "rb") as f:
            assert f.read() == sample["json"], key
        names = {"png": "image_filename", "flat.png": "mask_filename", "depth.png": "depth_filename",
                 "normal.png": "normal_filename", "albedo.png": "albedo_filename",
                 "shadow.png": "shadow_filename"}
        for ext, field in names.items():
            if meta.get(field):
                with open(os.path.join(folder, meta[field]), "rb") as f:
                    assert f.read() == sample[ext], (key, ext)
            else:
                assert ext not in sample, (key, ext)
        seen.setdefault(entry["split"], []).append(key)
    assert n == shard["samples"], (url, n, shard["samples"])
for split, keys in sorted(seen.items()):
    print(split, " ".join(keys))
"#;

#[test]
fn webdataset_shards_round_trip_through_the_webdataset_library() {
    let Some(blender) = blender_or_skip("webdataset_shards_round_trip") else {
        return;
    };
    let Some(python) = test_python_or_skip("webdataset_shards_round_trip", "webdataset") else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let (data, shards) = (dir.path().join("data"), dir.path().join("wds"));
    // 12 images: test = index 0 (int(1.2)), val = 1 (int(2.4)), train = 2..11.
    let o = clevrtex()
        .args(["generate", "--variant", "clevr", "-n", "12", "--seed", "2"])
        .args(["--width", "32", "--height", "24", "--samples", "1"])
        .args(["--passes", "rgb,mask,depth,normal", "--blender"])
        .arg(&blender)
        .arg("--out")
        .arg(&data)
        .output()
        .unwrap();
    assert_eq!(o.status.code(), Some(0), "{}", text(&o));
    // Small shards, so the train split spans several.
    let o = clevrtex()
        .args(["export", "--format", "webdataset", "--shard-size", "20000"])
        .arg(&data)
        .arg(&shards)
        .output()
        .unwrap();
    assert_eq!(o.status.code(), Some(0), "{}", text(&o));
    let index: serde_json::Value =
        serde_json::from_slice(&std::fs::read(shards.join("index.json")).unwrap()).unwrap();
    let train_shards = index["shards"]
        .as_array()
        .unwrap()
        .iter()
        .filter(|s| s["split"] == "train")
        .count();
    assert!(train_shards >= 2, "{index}");
    assert!(shards.join("clevr-test-000000.tar").is_file());
    assert!(shards.join("clevr-val-000000.tar").is_file());
    let leftovers: Vec<_> = std::fs::read_dir(&shards)
        .unwrap()
        .flatten()
        .filter(|e| e.file_name().to_string_lossy().contains("clevrtex-tmp"))
        .collect();
    assert!(leftovers.is_empty());

    let o = std::process::Command::new(&python)
        .args(["-c", READ_BACK])
        .arg(&shards)
        .arg(&data)
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", text(&o));
    let stdout = String::from_utf8_lossy(&o.stdout);
    let stem = |i: u64| format!("CLEVRTEX_clevr_{i:06}");
    let train: Vec<String> = (2..12).map(stem).collect();
    assert_eq!(
        stdout.lines().collect::<Vec<_>>(),
        [
            format!("test {}", stem(0)),
            format!("train {}", train.join(" ")),
            format!("val {}", stem(1)),
        ],
        "{stdout}"
    );

    // The same dataset exports to the same bytes.
    let again = dir.path().join("wds2");
    let o = clevrtex()
        .arg("export")
        .arg(&data)
        .arg(&again)
        .output()
        .unwrap();
    assert_eq!(o.status.code(), Some(0), "{}", text(&o));
    let o2 = clevrtex()
        .arg("export")
        .arg(&data)
        .arg(dir.path().join("wds3"))
        .output()
        .unwrap();
    assert_eq!(o2.status.code(), Some(0), "{}", text(&o2));
    for name in ["clevr-train-000000.tar", "clevr-test-000000.tar"] {
        assert_eq!(
            std::fs::read(again.join(name)).unwrap(),
            std::fs::read(dir.path().join("wds3").join(name)).unwrap(),
            "{name}"
        );
    }
}
