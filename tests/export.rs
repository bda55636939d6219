//! `clevrtex export --format webdataset`: shards read back by the real `webdataset` library
//! (in the test venv) equal the source files, split by split, in index order.

use crate::util::{blender_or_skip, clevrtex, test_python_or_skip, text};

/// Reads every shard of `index.json` with the real `webdataset` library, raw and through
/// `.decode("rgb")` (and `"torchrgb"` when torch is there), and with Hugging Face `datasets`'
/// `webdataset` builder, and checks each sample against the dataset's own files (found
/// through its metadata): PNGs byte for byte, `mask.npy` equal to the mask PNG's ids,
/// `depth.npy` to the depth PNG in metres (+inf background), `normal.npy` unit vectors; the
/// package's `clevrtex.wds.decode` gives the same from every reader. Prints `split keys...`
/// per split, then `torch: yes|no`.
const READ_BACK: &str = r#"
import io, json, os, sys
import numpy as np
from PIL import Image
import webdataset as wds
import datasets
import clevrtex
out, src = sys.argv[1], sys.argv[2]
index = json.load(open(os.path.join(out, "index.json")))
try:
    import torch
except ImportError:
    torch = None

def truth(meta, key):
    folder = os.path.join(src, "clevrtex_" + meta["variant"], str(meta["image_index"] // 1000))
    path = lambda field: os.path.join(folder, meta[field])
    if key == "mask":
        im = Image.open(path("mask_filename"))
        assert im.mode == "P", im.mode
        return np.array(im)
    if key == "depth":
        v = np.array(Image.open(path("depth_filename"))).astype(np.float64)
        assert meta["passes"]["depth"]["scale"] == 0.001
        return np.where(v == 65535, np.inf, v * 0.001).astype(np.float32)
    return open(path(key), "rb").read()

def same(a, b, what):
    assert a.dtype == b.dtype and a.shape == b.shape, (what, a.dtype, a.shape, b.dtype, b.shape)
    assert np.array_equal(a, b), what

seen = {}
for entry in index["shards"]:
    shard = entry["shard"]
    url = os.path.join(out, shard["file"])
    raw = list(wds.WebDataset(url, shardshuffle=False))
    rgb = list(wds.WebDataset(url, shardshuffle=False).decode("rgb"))
    assert len(raw) == len(rgb) == shard["samples"], (url, len(raw), shard["samples"])
    hf = datasets.load_dataset("webdataset", data_files={"x": [url]}, split="x")
    assert len(hf) == len(raw), (len(hf), len(raw))
    trgb = list(wds.WebDataset(url, shardshuffle=False).decode("torchrgb")) if torch else None
    for i, (r, d) in enumerate(zip(raw, rgb)):
        key = r["__key__"]
        # The record of one schema; the metadata file's text inside it.
        rec = json.loads(r["json"])
        meta = json.loads(rec["metadata"])
        assert rec["stem"] == meta["stem"] == key and d["__key__"] == key and hf[i]["__key__"] == key
        assert rec["split"] == meta["split"] and rec["index"] == meta["image_index"], key
        assert [o["shape"] for o in rec["objects"]] == [o["shape"] for o in meta["objects"]], key
        assert meta["split"] == entry["split"], (key, meta["split"], entry["split"])
        folder = os.path.join(src, "clevrtex_" + meta["variant"], str(meta["image_index"] // 1000))
        assert open(os.path.join(folder, key + ".json"), "rb").read() == rec["metadata"].encode(), key
        assert r["png"] == truth(meta, "image_filename"), key
        assert sorted(k for k in r if not k.startswith("__")) == ["depth.npy", "json", "mask.npy", "normal.npy", "png"], sorted(r)
        mask, depth = truth(meta, "mask"), truth(meta, "depth")
        assert mask.max() == meta["num_objects"], (key, mask.max())
        assert np.isfinite(depth).any() and depth[np.isfinite(depth)].min() > 0, key
        # `.decode("rgb")`: the image a float colour, the ids and metres as stored.
        assert d["png"].dtype == np.float32 and d["png"].shape == mask.shape + (3,), key
        same(d["mask.npy"], mask, (key, "rgb mask"))
        same(d["depth.npy"], depth, (key, "rgb depth"))
        n = d["normal.npy"]
        assert n.dtype == np.float32 and n.shape == mask.shape + (3,), (key, n.shape)
        length = np.linalg.norm(n, axis=-1)
        assert np.allclose(length[np.isfinite(depth)], 1, atol=1e-5), key
        assert (length[np.isinf(depth)] == 0).all(), key
        # Hugging Face: the same ids and metres.
        same(np.asarray(hf[i]["mask.npy"], dtype=np.uint8), mask, (key, "hf mask"))
        same(np.asarray(hf[i]["depth.npy"], dtype=np.float32), depth, (key, "hf depth"))
        # The package's decoder, from every reader's form of the sample.
        forms = [("raw", r), ("rgb", d), ("hf", hf[i])]
        if trgb is not None:
            forms.append(("torchrgb", trgb[i]))
            t = trgb[i]
            tm = t["mask.npy"]
            tm = tm.numpy() if hasattr(tm, "numpy") else np.asarray(tm)
            same(tm, mask, (key, "torchrgb mask"))
            td = t["depth.npy"]
            td = td.numpy() if hasattr(td, "numpy") else np.asarray(td)
            same(td, depth, (key, "torchrgb depth"))
        image = np.asarray(Image.open(io.BytesIO(r["png"])).convert("RGB"))
        for form, s in forms:
            a = clevrtex.wds.decode(s)
            assert a["key"] == key and a["metadata"]["stem"] == key, form
            same(a["mask"], mask, (key, form, "decode mask"))
            same(a["depth"], depth, (key, form, "decode depth"))
            same(a["image"], image, (key, form, "decode image"))
            assert a["normal"].shape == mask.shape + (3,), form
        seen.setdefault(entry["split"], []).append(key)
for split, keys in sorted(seen.items()):
    print(split, " ".join(keys))
print("torch:", "yes" if torch else "no")
"#;

#[test]
fn webdataset_shards_round_trip_through_the_webdataset_library() {
    let Some(blender) = blender_or_skip("webdataset_shards_round_trip") else {
        return;
    };
    let Some(python) = test_python_or_skip(
        "webdataset_shards_round_trip",
        "webdataset, datasets, PIL, clevrtex.wds",
    ) else {
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
    // The keys written by hand before they came from the pass table; what each holds.
    let keys: Vec<&str> = index["keys"]
        .as_array()
        .unwrap()
        .iter()
        .map(|k| k["key"].as_str().unwrap())
        .collect();
    assert_eq!(
        keys,
        [
            "__key__",
            "png",
            "mask.npy",
            "depth.npy",
            "normal.npy",
            "albedo.png",
            "shadow.npy",
            "json"
        ],
    );
    assert!(
        index["keys"][3]["holds"]
            .as_str()
            .unwrap()
            .starts_with("float32 (H, W) planar depth in metres"),
        "{index}"
    );
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
        // Hugging Face's cache in the test's folder, and no network.
        .env("HF_HOME", dir.path().join("hf"))
        .env("HF_DATASETS_OFFLINE", "1")
        .arg(&shards)
        .arg(&data)
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", text(&o));
    let stdout = String::from_utf8_lossy(&o.stdout);
    let stem = |i: u64| format!("CLEVRTEX_clevr_{i:06}");
    let train: Vec<String> = (2..12).map(stem).collect();
    let lines: Vec<&str> = stdout.lines().collect();
    assert_eq!(
        lines[..3],
        [
            format!("test {}", stem(0)),
            format!("train {}", train.join(" ")),
            format!("val {}", stem(1)),
        ],
        "{stdout}"
    );
    if lines.last() == Some(&"torch: no") {
        crate::util::skip(
            "webdataset_shards_round_trip (its `.decode(\"torchrgb\")` half)",
            crate::util::REQUIRE_TOOLS,
            "no torch in the test venv",
            "run `./scripts/setup.sh --torch`",
        );
    }

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

    // The published layout (metadata without our pass encodings): the mask's ids are still
    // an array; depth, in an encoding the metadata does not describe, stays its PNG.
    let published = dir.path().join("published");
    crate::util::published_copy(&data, "clevr", &published);
    let out = dir.path().join("wds-published");
    let (code, t) = export(&published, &out, &[]);
    assert_eq!(code, Some(0), "{t}");
    let names = members(&out.join("clevr-test-000000.tar"));
    assert_eq!(
        names,
        [
            "CLEVRTEX_clevr_000000.png",
            "CLEVRTEX_clevr_000000.mask.npy",
            "CLEVRTEX_clevr_000000.depth.png",
            "CLEVRTEX_clevr_000000.json"
        ],
        "{names:?}"
    );
}

/// A sample written by hand (no Blender): an 8-byte "PNG" (export does not decode) of
/// `png_bytes` bytes and metadata `meta` (with `image_filename` set to the layout's name
/// unless given).
fn hand_sample(out: &std::path::Path, index: u64, meta: serde_json::Value, png_bytes: usize) {
    let sub = out.join(format!("clevrtex_clevr/{}", index / 1000));
    std::fs::create_dir_all(&sub).unwrap();
    let stem = format!("CLEVRTEX_clevr_{index:06}");
    let mut meta = meta;
    if meta.get("image_filename").is_none() {
        meta["image_filename"] = format!("{stem}.png").into();
    }
    if meta.get("split").is_none() {
        meta["split"] = "train".into();
    }
    std::fs::write(sub.join(format!("{stem}.json")), meta.to_string()).unwrap();
    if png_bytes > 0 {
        std::fs::write(sub.join(format!("{stem}.png")), noise_png(png_bytes)).unwrap();
    }
}

/// An RGB PNG of noise, about `bytes` long (noise does not compress): export checks every
/// pass as the readers do, so a stand-in image must be a real one.
fn noise_png(bytes: usize) -> Vec<u8> {
    let h = (bytes / 96).max(1) as u32;
    let mut x = 0x2545_f491_u32;
    let img = image::RgbImage::from_fn(32, h, |_, _| {
        let mut px = [0u8; 3];
        for c in &mut px {
            x ^= x << 13;
            x ^= x >> 17;
            x ^= x << 5;
            *c = x as u8;
        }
        image::Rgb(px)
    });
    let mut out = Vec::new();
    img.write_to(&mut std::io::Cursor::new(&mut out), image::ImageFormat::Png)
        .unwrap();
    out
}

/// `clevrtex export DIR OUT extra...`, killed (a failure) after a minute.
fn export(dir: &std::path::Path, out: &std::path::Path, extra: &[&str]) -> (Option<i32>, String) {
    let mut child = clevrtex()
        .arg("export")
        .args(extra)
        .arg(dir)
        .arg(out)
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    let t = std::time::Instant::now();
    while child.try_wait().unwrap().is_none() {
        if t.elapsed().as_secs() > 60 {
            child.kill().unwrap();
            let o = child.wait_with_output().unwrap();
            panic!("export still running after a minute:\n{}", text(&o));
        }
        std::thread::sleep(std::time::Duration::from_millis(100));
    }
    let o = child.wait_with_output().unwrap();
    (o.status.code(), text(&o))
}

/// Member names of a tar file.
fn members(tar: &std::path::Path) -> Vec<String> {
    let mut a = tar::Archive::new(std::fs::File::open(tar).unwrap());
    a.entries()
        .unwrap()
        .map(|e| e.unwrap().path().unwrap().display().to_string())
        .collect()
}

#[test]
fn export_takes_file_names_from_the_layout_and_splits_from_the_fixed_set() {
    let dir = tempfile::tempdir().unwrap();
    let data = dir.path().join("data");
    let secret = dir.path().join("secret.txt");
    std::fs::write(&secret, b"not the dataset's").unwrap();
    hand_sample(
        &data,
        0,
        serde_json::json!({"image_filename": secret.display().to_string()}),
        100,
    );
    let out = dir.path().join("wds");
    let (code, t) = export(&data, &out, &[]);
    assert_eq!(code, Some(1), "{t}");
    assert!(
        t.contains("CLEVRTEX_clevr_000000.json` key `image_filename` is"),
        "{t}"
    );
    assert!(
        t.contains("not the layout's `CLEVRTEX_clevr_000000.png`"),
        "{t}"
    );

    let data = dir.path().join("data2");
    hand_sample(&data, 0, serde_json::json!({"split": "../../escaped"}), 100);
    let out = dir.path().join("deep/er/wds");
    let (code, t) = export(&data, &out, &[]);
    assert_eq!(code, Some(1), "{t}");
    assert!(
        t.contains("key `split` is `../../escaped`, not test, val or train"),
        "{t}"
    );
    let escaped: Vec<_> = std::fs::read_dir(dir.path())
        .unwrap()
        .flatten()
        .filter(|e| e.file_name().to_string_lossy().contains("escaped"))
        .collect();
    assert!(escaped.is_empty(), "a shard was written outside OUT");
}

/// Metadata goes through the dataset reader's check, as in `preview`, `report`, `eval` and
/// the Python `Dataset`: export packs no sample whose metadata that check rejects.
#[test]
fn export_refuses_metadata_the_dataset_reader_rejects() {
    let dir = tempfile::tempdir().unwrap();
    let data = dir.path().join("data");
    hand_sample(&data, 0, serde_json::json!({}), 100);
    hand_sample(&data, 1, serde_json::json!({"objects": 5}), 100);
    let out = dir.path().join("wds");
    let (code, t) = export(&data, &out, &[]);
    assert_eq!(code, Some(1), "{t}");
    assert!(
        t.contains("CLEVRTEX_clevr_000001.json` key `objects` is 5, not a list"),
        "{t}"
    );
    assert!(t.contains("clevrtex verify"), "{t}");
    // Metadata that lists no pass at all: nothing but the JSON would be packed.
    let data = dir.path().join("data2");
    hand_sample(&data, 0, serde_json::json!({"image_filename": null}), 0);
    let (code, t) = export(&data, &out, &[]);
    assert_eq!(code, Some(1), "{t}");
    assert!(
        t.contains("CLEVRTEX_clevr_000000.json` lists no pass"),
        "{t}"
    );
}

#[test]
fn export_follows_no_link_out_of_the_dataset_and_reads_no_fifo() {
    let dir = tempfile::tempdir().unwrap();
    let data = dir.path().join("data");
    let secret = dir.path().join("secret.png");
    std::fs::write(&secret, b"not the dataset's").unwrap();
    for i in 0..3 {
        hand_sample(
            &data,
            i,
            serde_json::json!({}),
            if i == 2 { 100 } else { 0 },
        );
    }
    let sub = data.join("clevrtex_clevr/0");
    std::os::unix::fs::symlink(&secret, sub.join("CLEVRTEX_clevr_000000.png")).unwrap();
    let st = std::process::Command::new("mkfifo")
        .arg(sub.join("CLEVRTEX_clevr_000001.png"))
        .status()
        .unwrap();
    assert!(st.success());
    let out = dir.path().join("wds");
    let (code, t) = export(&data, &out, &[]);
    assert_eq!(code, Some(3), "{t}");
    assert!(
        t.contains("CLEVRTEX_clevr_000000.png` is a symbolic link leading out of the dataset"),
        "{t}"
    );
    assert!(
        t.contains("CLEVRTEX_clevr_000001.png` is not a regular file"),
        "{t}"
    );
    assert_eq!(
        members(&out.join("clevr-train-000000.tar")),
        ["CLEVRTEX_clevr_000002.png", "CLEVRTEX_clevr_000002.json"]
    );
}

#[test]
fn export_removes_the_shards_of_an_earlier_export_it_did_not_write() {
    let dir = tempfile::tempdir().unwrap();
    let data = dir.path().join("data");
    for i in 0..3 {
        hand_sample(&data, i, serde_json::json!({}), 6000);
    }
    let out = dir.path().join("wds");
    std::fs::create_dir_all(&out).unwrap();
    std::fs::write(out.join("notes.tar"), b"mine").unwrap();
    std::fs::write(out.join("other-name-1.tar"), b"mine").unwrap();
    let (code, t) = export(&data, &out, &["--shard-size", "10240"]);
    assert_eq!(code, Some(0), "{t}");
    assert!(out.join("clevr-train-000002.tar").is_file(), "{t}");
    std::fs::remove_dir_all(data.join("clevrtex_clevr")).unwrap();
    hand_sample(&data, 0, serde_json::json!({}), 6000);
    let (code, t) = export(&data, &out, &["--shard-size", "10240"]);
    assert_eq!(code, Some(0), "{t}");
    let mut left: Vec<String> = std::fs::read_dir(&out)
        .unwrap()
        .flatten()
        .map(|e| e.file_name().to_string_lossy().into_owned())
        .collect();
    left.sort();
    assert_eq!(
        left,
        [
            "clevr-train-000000.tar",
            "ids.json",
            "index.json",
            "notes.tar",
            "other-name-1.tar"
        ]
    );
    let index: serde_json::Value =
        serde_json::from_slice(&std::fs::read(out.join("index.json")).unwrap()).unwrap();
    assert_eq!(index["shards"].as_array().unwrap().len(), 1, "{index}");
}

/// A file named like a shard that no export wrote (hostile pass, issue 21: export replaced or
/// removed it) is refused before anything is written, and left as it was.
#[test]
fn export_leaves_a_file_named_like_a_shard_that_is_not_one() {
    let dir = tempfile::tempdir().unwrap();
    let data = dir.path().join("data");
    hand_sample(&data, 0, serde_json::json!({}), 600);
    let out = dir.path().join("wds");
    std::fs::create_dir_all(&out).unwrap();
    for name in ["clevr-train-000000.tar", "clevr-val-000007.tar"] {
        let mine = out.join(name);
        std::fs::write(&mine, b"my notes, not a tar file").unwrap();
        let (code, t) = export(&data, &out, &[]);
        assert_eq!(code, Some(1), "{t}");
        assert!(
            t.contains(&format!(
                "{name}` is named like a shard but is not a tar file"
            )),
            "{t}"
        );
        assert_eq!(std::fs::read(&mine).unwrap(), b"my notes, not a tar file");
        assert!(!out.join("index.json").exists(), "{t}");
        std::fs::remove_file(&mine).unwrap();
    }
    // A shard an export wrote is replaced as before.
    let (code, t) = export(&data, &out, &[]);
    assert_eq!(code, Some(0), "{t}");
    let (code, t) = export(&data, &out, &[]);
    assert_eq!(code, Some(0), "{t}");
}

/// Hostile pass (issue 21, minor): an OUT inside the dataset (`export DIR DIR/clevrtex_clevr/x`)
/// is refused, as `preview` and `report` refuse an `--out` there; shards were written into the
/// dataset without a word.
#[test]
fn export_refuses_an_out_inside_the_dataset() {
    let dir = tempfile::tempdir().unwrap();
    let data = dir.path().join("data");
    hand_sample(&data, 0, serde_json::json!({}), 600);
    for out in [data.join("wds"), data.join("clevrtex_clevr/wds/new")] {
        let (code, t) = export(&data, &out, &[]);
        assert_eq!(code, Some(1), "{t}");
        assert!(t.contains("is inside the dataset"), "{t}");
        assert!(!out.exists(), "{t}");
    }
    let (code, t) = export(&data, &dir.path().join("wds"), &[]);
    assert_eq!(code, Some(0), "{t}");
}

/// A sample of our layout written by hand: metadata with the size 32x24, `n` objects and the
/// passes of `files` (suffix, PNG bytes, pass name), so that every reader types it whole.
fn checked_sample(out: &std::path::Path, index: u64, n: usize, files: &[(&str, Vec<u8>, &str)]) {
    let sub = out.join(format!("clevrtex_clevr/{}", index / 1000));
    std::fs::create_dir_all(&sub).unwrap();
    let stem = format!("CLEVRTEX_clevr_{index:06}");
    let mut meta = serde_json::json!({
        "image_index": index, "variant": "clevr", "split": "train",
        "render": {"width": 32, "height": 24}, "num_objects": n,
        "objects": vec![serde_json::json!({"shape": "cube"}); n], "passes": {},
    });
    for (suffix, bytes, pass) in files {
        let name = format!("{stem}{suffix}.png");
        std::fs::write(sub.join(&name), bytes).unwrap();
        let key = if *pass == "rgb" {
            "image_filename".to_string()
        } else {
            format!("{pass}_filename")
        };
        meta[key] = name.into();
        meta["passes"][*pass] = serde_json::json!({});
    }
    std::fs::write(sub.join(format!("{stem}.json")), meta.to_string()).unwrap();
}

fn png_of(img: impl Into<image::DynamicImage>) -> Vec<u8> {
    let mut out = Vec::new();
    img.into()
        .write_to(&mut std::io::Cursor::new(&mut out), image::ImageFormat::Png)
        .unwrap();
    out
}

/// Issue 42, finding 7: `export` packed what every other reader refuses. Its passes now go
/// through the checks of `verify` (`check_pass_png`): each refused sample is left out by name,
/// exit 3, and the others are packed.
#[test]
fn export_leaves_out_the_samples_every_reader_refuses() {
    let dir = tempfile::tempdir().unwrap();
    let data = dir.path().join("data");
    let rgb = || {
        png_of(image::RgbImage::from_pixel(
            32,
            24,
            image::Rgb([90, 120, 150]),
        ))
    };
    let mask = |w, h, id| png_of(image::GrayImage::from_pixel(w, h, image::Luma([id])));
    let depth = |w, h| {
        png_of(
            image::ImageBuffer::<image::Luma<u16>, Vec<u16>>::from_pixel(
                w,
                h,
                image::Luma([900u16]),
            ),
        )
    };
    checked_sample(
        &data,
        0,
        4,
        &[
            ("", rgb(), "rgb"),
            ("_flat", mask(32, 24, 4), "mask"),
            ("_depth_0001", depth(32, 24), "depth"),
        ],
    );
    checked_sample(
        &data,
        1,
        4,
        &[("", rgb(), "rgb"), ("_flat", mask(4096, 4096, 1), "mask")],
    );
    checked_sample(
        &data,
        2,
        4,
        &[("", rgb(), "rgb"), ("_depth_0001", depth(33, 24), "depth")],
    );
    // A header declaring 100000x100000 (never decoded).
    let mut huge = rgb();
    huge[16..20].copy_from_slice(&100_000u32.to_be_bytes());
    huge[20..24].copy_from_slice(&100_000u32.to_be_bytes());
    checked_sample(&data, 3, 4, &[("", huge, "rgb")]);
    checked_sample(
        &data,
        4,
        4,
        &[("", rgb(), "rgb"), ("_flat", mask(32, 24, 200), "mask")],
    );
    let albedo = rgb();
    checked_sample(
        &data,
        5,
        4,
        &[
            ("", rgb(), "rgb"),
            (
                "_albedo_0001",
                albedo[..albedo.len() / 2].to_vec(),
                "albedo",
            ),
        ],
    );
    let out = dir.path().join("wds");
    let (code, t) = export(&data, &out, &[]);
    assert_eq!(code, Some(3), "{t}");
    for (index, what) in [
        (
            1,
            "CLEVRTEX_clevr_000001_flat.png` is 4096x4096 (the metadata says 32x24)",
        ),
        (
            2,
            "CLEVRTEX_clevr_000002_depth_0001.png` is 33x24 (the metadata says 32x24)",
        ),
        (
            3,
            "CLEVRTEX_clevr_000003.png` is 100000x100000 (the metadata says 32x24)",
        ),
        (4, "mask has id 200 but the metadata has 4 objects"),
        (
            5,
            "CLEVRTEX_clevr_000005_albedo_0001.png`: cannot decode PNG",
        ),
    ] {
        assert!(t.contains(what), "sample {index}: {t}");
        assert!(
            t.contains(&format!("(sample `CLEVRTEX_clevr_{index:06}` left out)")),
            "{index}: {t}"
        );
    }
    assert_eq!(
        members(&out.join("clevr-train-000000.tar")),
        [
            "CLEVRTEX_clevr_000000.png",
            "CLEVRTEX_clevr_000000.mask.npy",
            "CLEVRTEX_clevr_000000.depth.npy",
            "CLEVRTEX_clevr_000000.json"
        ]
    );
    // The COCO export reads through the same reader and checks: the image and the mask of
    // each sample pass them, or the sample is left out by name (exit 3).
    let coco_data = dir.path().join("coco-data");
    let mut huge = rgb();
    huge[16..20].copy_from_slice(&100_000u32.to_be_bytes());
    huge[20..24].copy_from_slice(&100_000u32.to_be_bytes());
    for (index, image, m) in [
        (0, rgb(), mask(32, 24, 4)),
        (1, rgb(), mask(4096, 4096, 1)),
        (3, huge, mask(32, 24, 1)),
        (4, rgb(), mask(32, 24, 200)),
    ] {
        checked_sample(
            &coco_data,
            index,
            4,
            &[("", image, "rgb"), ("_flat", m, "mask")],
        );
    }
    let coco = dir.path().join("coco");
    let (code, t) = export(&coco_data, &coco, &["--format", "coco"]);
    assert_eq!(code, Some(3), "{t}");
    for index in [1, 3, 4] {
        assert!(
            t.contains(&format!("(sample `CLEVRTEX_clevr_{index:06}` left out)")),
            "{index}: {t}"
        );
    }
    let doc: serde_json::Value =
        serde_json::from_slice(&std::fs::read(coco.join("clevr-train.json")).unwrap()).unwrap();
    let stems: Vec<&str> = doc["images"]
        .as_array()
        .unwrap()
        .iter()
        .map(|i| i["stem"].as_str().unwrap())
        .collect();
    assert_eq!(stems, ["CLEVRTEX_clevr_000000"], "{doc}");
    assert_eq!(doc["annotations"].as_array().unwrap().len(), 1, "{doc}");
}

/// The fixture of `tests/export_pipelines/fixture.py` (no Blender): `specs` such as
/// `clevr:10`, written into `dir/data`.
fn python_fixture(
    python: &std::path::Path,
    dir: &std::path::Path,
    specs: &[&str],
) -> std::path::PathBuf {
    let data = dir.join("data");
    let o = std::process::Command::new(python)
        .arg(crate::util::repo_root().join("tests/export_pipelines/fixture.py"))
        .arg(&data)
        .args(specs)
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", text(&o));
    data
}

/// A check script of `tests/export_pipelines/` run with `args` (Hugging Face's cache in `hf`,
/// offline); its stdout.
fn python_check(
    python: &std::path::Path,
    script: &str,
    args: &[&std::ffi::OsStr],
    hf: &std::path::Path,
) -> String {
    let o = std::process::Command::new(python)
        .arg(
            crate::util::repo_root()
                .join("tests/export_pipelines")
                .join(script),
        )
        .args(args)
        .env("HF_HOME", hf)
        .env("HF_DATASETS_OFFLINE", "1")
        .output()
        .unwrap();
    assert!(o.status.success(), "{script}:\n{}", text(&o));
    String::from_utf8_lossy(&o.stdout).into_owned()
}

/// Issue 43: `export --format coco` gives one COCO file per variant and split that pycocotools
/// reads with every object's mask, box, area, category and attributes exact (images in place,
/// and copied with `--split`); a sample the reader refuses is left out by name (exit 3); an
/// unknown format or split, an OUT inside the dataset, a split without samples: a clear
/// message and nothing written.
#[test]
fn coco_export_reads_back_exactly_through_pycocotools() {
    let test = "coco_export_reads_back_exactly_through_pycocotools";
    let Some(python) = test_python_or_skip(test, "pycocotools, PIL, clevrtex") else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let data = python_fixture(&python, dir.path(), &["clevr:10", "camo:10"]);
    let out = dir.path().join("coco");
    let (code, t) = export(&data, &out, &["--format", "coco"]);
    assert_eq!(code, Some(0), "{t}");
    let hf = dir.path().join("hf");
    let stdout = python_check(
        &python,
        "coco_check.py",
        &[out.as_os_str(), data.as_os_str()],
        &hf,
    );
    // 10 samples: test 1, val 1, train 8; 2-4 objects each, object 0 hidden in every fourth.
    assert_eq!(
        stdout.lines().collect::<Vec<_>>(),
        [
            "camo test 1 2",
            "camo train 8 22",
            "camo val 1 3",
            "clevr test 1 2",
            "clevr train 8 22",
            "clevr val 1 3"
        ],
        "{stdout}"
    );
    let doc: serde_json::Value =
        serde_json::from_slice(&std::fs::read(out.join("clevr-train.json")).unwrap()).unwrap();
    let names: Vec<&str> = doc["categories"]
        .as_array()
        .unwrap()
        .iter()
        .map(|c| c["name"].as_str().unwrap())
        .collect();
    // The dataset's one shape table (issue 49), the same in every file: id = shape id + 1.
    assert_eq!(
        names,
        [
            "cube",
            "sphere",
            "cylinder",
            "monkey",
            "cone",
            "torus",
            "icosahedron",
            "teapot"
        ],
        "{}",
        doc["categories"]
    );
    assert!(doc["images"][0]["file_name"]
        .as_str()
        .unwrap()
        .starts_with('/'));

    // Copied images, one split.
    let copied = dir.path().join("coco-copied");
    let (code, t) = export(
        &data,
        &copied,
        &["--format", "coco", "--split", "val", "--copy-images"],
    );
    assert_eq!(code, Some(0), "{t}");
    assert!(copied.join("images/CLEVRTEX_clevr_000001.png").is_file());
    let stdout = python_check(
        &python,
        "coco_check.py",
        &[copied.as_os_str(), data.as_os_str()],
        &hf,
    );
    assert_eq!(
        stdout.lines().collect::<Vec<_>>(),
        ["camo val 1 3", "clevr val 1 3"]
    );

    // Bad input: nothing written.
    for (args, code_want, says) in [
        (
            &["--format", "yolo"][..],
            2,
            "invalid value 'yolo' for '--format",
        ),
        (
            &["--format", "coco", "--split", "dev"],
            2,
            "invalid value 'dev' for '--split",
        ),
        (
            &["--format", "coco", "--split", "test", "--variant", "nope"],
            1,
            "no `clevrtex_<variant>` folder for `nope`",
        ),
    ] {
        let fresh = dir.path().join("not-written");
        let (code, t) = export(&data, &fresh, args);
        assert_eq!(code, Some(code_want), "{args:?}: {t}");
        assert!(t.contains(says), "{args:?}: {t}");
        assert!(!fresh.exists(), "{args:?}: {t}");
    }
    let inside = data.join("clevrtex_clevr/coco");
    let (code, t) = export(&data, &inside, &["--format", "coco"]);
    assert_eq!(code, Some(1), "{t}");
    assert!(t.contains("is inside the dataset"), "{t}");
    assert!(!inside.exists());
    // A 4-sample dataset has no test sample (int(0.4) = 0).
    let small = python_fixture(&python, &dir.path().join("small"), &["clevr:4"]);
    let fresh = dir.path().join("not-written");
    let (code, t) = export(&small, &fresh, &["--format", "coco", "--split", "test"]);
    assert_eq!(code, Some(1), "{t}");
    assert!(
        t.contains("no sample to export in split `test`")
            && t.contains("clevr: test 0, val 0, train 4"),
        "{t}"
    );
    assert!(!fresh.exists(), "{t}");

    // A sample behind a link out of the dataset: left out by name, the rest exported, exit 3.
    let sub = small.join("clevrtex_clevr/0");
    let secret = dir.path().join("secret.png");
    std::fs::rename(sub.join("CLEVRTEX_clevr_000002_flat.png"), &secret).unwrap();
    std::os::unix::fs::symlink(&secret, sub.join("CLEVRTEX_clevr_000002_flat.png")).unwrap();
    let out = dir.path().join("coco-partial");
    let (code, t) = export(&small, &out, &["--format", "coco"]);
    assert_eq!(code, Some(3), "{t}");
    assert!(
        t.contains("CLEVRTEX_clevr_000002_flat.png` is a symbolic link leading out of the dataset"),
        "{t}"
    );
    let doc: serde_json::Value =
        serde_json::from_slice(&std::fs::read(out.join("clevr-train.json")).unwrap()).unwrap();
    let stems: Vec<&str> = doc["images"]
        .as_array()
        .unwrap()
        .iter()
        .map(|i| i["stem"].as_str().unwrap())
        .collect();
    assert_eq!(
        stems,
        [
            "CLEVRTEX_clevr_000000",
            "CLEVRTEX_clevr_000001",
            "CLEVRTEX_clevr_000003"
        ]
    );
}

/// Issue 42, minor: a killed `export` left its temporary shard, which the rerun kept. The rerun
/// removes the temporaries it can prove are a dead export's (a shard's name, this host, a dead
/// owner, a tar), and nothing else.
#[test]
fn export_removes_the_temporary_shards_of_killed_exports_only() {
    let dir = tempfile::tempdir().unwrap();
    let data = dir.path().join("data");
    hand_sample(&data, 0, serde_json::json!({}), 100);
    let out = dir.path().join("wds");
    std::fs::create_dir_all(&out).unwrap();
    let mut tar = tar::Builder::new(Vec::new());
    let mut h = tar::Header::new_ustar();
    h.set_size(4);
    h.set_cksum();
    tar.append_data(&mut h, "x.png", &b"half"[..]).unwrap();
    let tar = tar.into_inner().unwrap();
    let mut gone = std::process::Command::new("true").spawn().unwrap();
    let dead = gone.id();
    gone.wait().unwrap();
    let me = std::process::id();
    let my_start = {
        let stat = std::fs::read_to_string("/proc/self/stat").unwrap();
        let rest = stat[stat.rfind(')').unwrap() + 1..].to_string();
        rest.split_whitespace().nth(19).unwrap().to_string()
    };
    let killed = out.join(format!("clevr-train-000003.tar.h42.{dead}.1.clevrtex-tmp"));
    let live = out.join(format!(
        "clevr-train-000004.tar.h42.{me}.{my_start}.clevrtex-tmp"
    ));
    let other_host = out.join(format!(
        "clevr-train-000005.tar.elsewhere.{dead}.1.clevrtex-tmp"
    ));
    let not_a_shard = out.join(format!("notes.tar.h42.{dead}.1.clevrtex-tmp"));
    let not_a_tar = out.join(format!("clevr-train-000006.tar.h42.{dead}.1.clevrtex-tmp"));
    for p in [&killed, &live, &other_host, &not_a_shard] {
        std::fs::write(p, &tar).unwrap();
    }
    std::fs::write(&not_a_tar, vec![7u8; 1024]).unwrap();
    let o = clevrtex()
        .arg("export")
        .arg(&data)
        .arg(&out)
        .env("CLEVRTEX_HOST", "h42")
        .output()
        .unwrap();
    let t = text(&o);
    assert_eq!(o.status.code(), Some(0), "{t}");
    assert!(!killed.exists(), "{t}");
    assert!(
        t.contains("removed 1 temporary shard(s) of killed exports: clevr-train-000003.tar."),
        "{t}"
    );
    for p in [&live, &other_host, &not_a_shard, &not_a_tar] {
        assert!(p.is_file(), "`{}` was removed: {t}", p.display());
    }
}

/// Issue 42, minor: `--shard-size 1` was accepted by `--help`'s range and refused by the
/// command with another one. One range, 10240 to 10^12, in both (and in README.md).
#[test]
fn shard_size_has_one_range() {
    let o = clevrtex()
        .args(["export", "--shard-size", "10239", "a", "b"])
        .output()
        .unwrap();
    assert_eq!(o.status.code(), Some(2), "{}", text(&o));
    assert!(text(&o).contains("10240..=1000000000000"), "{}", text(&o));
    let help = clevrtex().args(["export", "--help"]).output().unwrap();
    assert!(text(&help).contains("10240 to 10^12"), "{}", text(&help));
    let readme = std::fs::read_to_string(crate::util::repo_root().join("README.md")).unwrap();
    assert!(readme.contains("| `--shard-size` (`export`) | 10240 to 10^12 bytes |"));
}

/// Issue 43: shards of two variants (`color` null on `camo`, a string on `clevr`; a key on some
/// samples only) load together with Hugging Face `datasets`, with `--objects K` per-object
/// arrays whose ids index `index.json`'s name tables; ids and metres exact through
/// `clevrtex.wds.decode`, also as torch tensors; `--crop --resize 16` gives the Python
/// `Dataset`'s (the public loader's) cropped and resized items.
#[test]
fn webdataset_shards_of_several_variants_load_together_in_hugging_face() {
    let test = "webdataset_shards_of_several_variants_load_together_in_hugging_face";
    let Some(python) = test_python_or_skip(test, "datasets, PIL, clevrtex.wds") else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let data = python_fixture(&python, dir.path(), &["clevr:10", "camo:10"]);
    let out = dir.path().join("wds");
    let (code, t) = export(&data, &out, &["--objects", "6"]);
    assert_eq!(code, Some(0), "{t}");
    let index: serde_json::Value =
        serde_json::from_slice(&std::fs::read(out.join("index.json")).unwrap()).unwrap();
    assert_eq!(index["objects"], 6, "{index}");
    assert_eq!(index["names"]["shape"][0], "cube", "{index}");
    let stdout = python_check(
        &python,
        "hf_check.py",
        &[out.as_os_str(), data.as_os_str()],
        &dir.path().join("hf"),
    );
    let last = stdout.lines().last().unwrap_or_default();
    assert!(
        last.starts_with("variants: camo clevr samples: 20 torch: "),
        "{stdout}"
    );
    if last.ends_with("torch: no") {
        crate::util::skip(
            "webdataset_shards_of_several_variants_load_together_in_hugging_face (its torch half)",
            crate::util::REQUIRE_TOOLS,
            "no torch in the test venv",
            "run `./scripts/setup.sh --torch`",
        );
    }
    // `--crop --resize N`: the public loader's items, as the Python `Dataset` gives them.
    let cropped = dir.path().join("wds-cropped");
    let (code, t) = export(
        &data,
        &cropped,
        &["--crop", "--resize", "16", "--objects", "6"],
    );
    assert_eq!(code, Some(0), "{t}");
    let stdout = python_check(
        &python,
        "crop_check.py",
        &[
            cropped.as_os_str(),
            data.as_os_str(),
            "16".as_ref(),
            "6".as_ref(),
        ],
        &dir.path().join("hf"),
    );
    assert_eq!(stdout.trim(), "samples: 20", "{stdout}");
    let (code, t) = export(&data, &dir.path().join("not-written"), &["--resize", "16"]);
    assert_eq!(code, Some(1), "{t}");
    assert!(
        t.contains("`--resize` resizes the centre crop") && t.contains("add `--crop`"),
        "{t}"
    );
    assert!(!dir.path().join("not-written").exists());
    // More objects than K: named.
    let fresh = dir.path().join("too-few");
    let (code, t) = export(&data, &fresh, &["--objects", "3"]);
    assert_eq!(code, Some(1), "{t}");
    assert!(t.contains("has 4 objects, more than `--objects 3`"), "{t}");
}

/// Issue 48: the exports leave out exactly what `verify` refuses, named, with a non-zero exit:
/// a sample of a `generate` run whose recorded split was forged (the manifest's hashes
/// rewritten to match) no longer lands in the test split's COCO file, and one whose metadata
/// gives an object another box than its mask is left out; COCO's `attributes.bbox` is the
/// mask's box.
#[test]
fn exports_leave_out_what_verify_refuses() {
    let Some(blender) = blender_or_skip("exports leave out what verify refuses") else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let data = dir.path().join("data");
    let o = clevrtex()
        .args(["generate", "--variant", "clevr", "-n", "3", "--seed", "2"])
        .args(["--width", "32", "--height", "24", "--samples", "1"])
        .args(["--passes", "rgb,mask", "--workers", "1", "--blender"])
        .arg(&blender)
        .arg("--out")
        .arg(&data)
        .env_remove("SLURM_ARRAY_TASK_ID")
        .env_remove("JOB_COMPLETION_INDEX")
        .output()
        .unwrap();
    assert_eq!(o.status.code(), Some(0), "{}", text(&o));
    let vdir = data.join("clevrtex_clevr");
    let manifest = vdir.join("MANIFEST-0-3-0of1.json");
    let forge = |index: u64, f: &dyn Fn(&mut serde_json::Value)| {
        let rel = format!("0/CLEVRTEX_clevr_{index:06}.json");
        let p = vdir.join(&rel);
        let mut m: serde_json::Value = serde_json::from_slice(&std::fs::read(&p).unwrap()).unwrap();
        f(&mut m);
        let bytes = serde_json::to_vec_pretty(&m).unwrap();
        std::fs::write(&p, &bytes).unwrap();
        let mut man: serde_json::Value =
            serde_json::from_slice(&std::fs::read(&manifest).unwrap()).unwrap();
        man["files"][&rel]["xxh3"] = clevrtex_dataset::manifest::hash_hex(&bytes).into();
        man["files"][&rel]["size"] = bytes.len().into();
        std::fs::write(&manifest, serde_json::to_vec_pretty(&man).unwrap()).unwrap();
    };
    // Untouched: every sample exported, and the attributes' box is the mask's.
    let out = dir.path().join("coco0");
    let (code, t) = export(&data, &out, &["--format", "coco"]);
    assert_eq!(code, Some(0), "{t}");
    let doc: serde_json::Value =
        serde_json::from_slice(&std::fs::read(out.join("clevr-train.json")).unwrap()).unwrap();
    for a in doc["annotations"].as_array().unwrap() {
        let b: Vec<u64> = a["bbox"]
            .as_array()
            .unwrap()
            .iter()
            .map(|v| v.as_u64().unwrap())
            .collect();
        assert_eq!(
            a["attributes"]["bbox"],
            serde_json::json!([b[0], b[1], b[0] + b[2] - 1, b[1] + b[3] - 1]),
            "{a}"
        );
    }

    forge(1, &|m| m["split"] = "test".into());
    forge(2, &|m| {
        m["objects"][0]["bbox"] = serde_json::json!([0, 0, 1, 1])
    });
    let o = crate::util::run(&["verify", data.to_str().unwrap()]);
    assert_eq!(o.status.code(), Some(3), "{}", text(&o));
    for format in ["coco", "webdataset"] {
        let out = dir.path().join(format!("out-{format}"));
        let (code, t) = export(&data, &out, &["--format", format]);
        assert_ne!(code, Some(0), "{format}: {t}");
        for stem in ["CLEVRTEX_clevr_000001", "CLEVRTEX_clevr_000002"] {
            assert!(
                t.contains(&format!("sample `{stem}` is refused by `clevrtex verify`")),
                "{format}: {stem} not named: {t}"
            );
        }
        if format == "coco" {
            let test = out.join("clevr-test.json");
            if test.exists() {
                let doc = std::fs::read_to_string(&test).unwrap();
                assert!(!doc.contains("CLEVRTEX_clevr_000001"), "{doc}");
            }
            let train = std::fs::read_to_string(out.join("clevr-train.json")).unwrap();
            assert!(
                train.contains("CLEVRTEX_clevr_000000") && !train.contains("CLEVRTEX_clevr_000002"),
                "{train}"
            );
        }
    }
}
