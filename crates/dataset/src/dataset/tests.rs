use std::path::Path;

use clevrtex_scene::Pass;
use serde_json::Value;

use super::*;
use crate::layout;

#[test]
fn links_out_and_fifos_are_not_read() {
    let dir = tempfile::tempdir().unwrap();
    let outside = tempfile::tempdir().unwrap();
    let data = dir.path().join("data");
    std::fs::create_dir(&data).unwrap();
    std::fs::write(outside.path().join("secret"), b"s").unwrap();
    std::fs::write(data.join("a.json"), b"{}").unwrap();
    std::os::unix::fs::symlink(outside.path().join("secret"), data.join("out.png")).unwrap();
    std::os::unix::fs::symlink(data.join("a.json"), data.join("in.json")).unwrap();
    std::os::unix::fs::symlink("/dev/zero", data.join("zero.png")).unwrap();
    let fifo = data.join("fifo.png");
    assert!(std::process::Command::new("mkfifo")
        .arg(&fifo)
        .status()
        .unwrap()
        .success());
    let root = root(&data).unwrap();
    assert_eq!(read(&root, &data.join("a.json"), 10).unwrap(), b"{}");
    assert_eq!(read(&root, &data.join("in.json"), 10).unwrap(), b"{}");
    assert!(read(&root, &data.join("out.png"), 10)
        .unwrap_err()
        .contains("leading out of the dataset"));
    assert!(read(&root, &data.join("zero.png"), 10)
        .unwrap_err()
        .contains("leading out of the dataset"));
    assert!(read(&root, &fifo, 10)
        .unwrap_err()
        .contains("not a regular file"));
    assert!(read(&root, &data.join("a.json"), 1)
        .unwrap_err()
        .contains("over the 1 bytes"));
}

fn mkfifo(p: &Path) {
    assert!(std::process::Command::new("mkfifo")
        .arg(p)
        .status()
        .unwrap()
        .success());
}

#[test]
fn open_finds_samples_and_what_does_not_belong() {
    let dir = tempfile::tempdir().unwrap();
    let outside = tempfile::tempdir().unwrap();
    std::fs::write(outside.path().join("secret.json"), b"{}").unwrap();
    let out = dir.path().join("out");
    let v = out.join("clevrtex_camo");
    let s0 = v.join("0");
    std::fs::create_dir_all(&s0).unwrap();
    let stem = layout::stem("camo", 3);
    for pass in [Pass::Rgb, Pass::Mask] {
        std::fs::write(s0.join(layout::pass_file(&stem, pass)), b"png").unwrap();
    }
    std::fs::write(s0.join(layout::metadata_file(&stem)), b"{}").unwrap();
    // A sample whose metadata leads out of the dataset, one whose mask is a FIFO.
    let out_stem = layout::stem("camo", 4);
    std::fs::write(s0.join(layout::pass_file(&out_stem, Pass::Rgb)), b"png").unwrap();
    std::os::unix::fs::symlink(
        outside.path().join("secret.json"),
        s0.join(layout::metadata_file(&out_stem)),
    )
    .unwrap();
    mkfifo(&s0.join(layout::pass_file(&stem, Pass::Depth)));
    std::fs::write(s0.join("notes.txt"), b"x").unwrap();
    std::fs::write(s0.join(".CLEVRTEX_camo_000005.png.tmp1"), b"x").unwrap();
    std::fs::create_dir(s0.join(layout::pass_file(&layout::stem("camo", 6), Pass::Albedo)))
        .unwrap();
    std::fs::write(v.join("MANIFEST-0-8-0of1.json"), b"not json").unwrap();
    std::fs::write(
        v.join(layout::LEDGER_FILE),
        b"{\"variant\":\"camo\",\"index\":7,\"error\":\"boom\"}\nnot json\n",
    )
    .unwrap();
    std::fs::write(v.join("x.clevrtex-tmp"), b"").unwrap();
    std::fs::write(v.join("README"), b"").unwrap();
    std::os::unix::fs::symlink(outside.path(), out.join("clevrtex_away")).unwrap();
    // A copy of a sample at the variant root (issue 34: the public loader's `**/` glob
    // reads it a second time; `verify` ignored it).
    std::fs::write(v.join(layout::metadata_file(&stem)), b"{}").unwrap();

    let ds = Dataset::open(&out).unwrap();
    assert!(!ds.is_variant_dir);
    assert_eq!(ds.variants.len(), 1);
    assert_eq!(ds.skipped.len(), 1);
    assert_eq!(ds.skipped[0].0, "away");
    assert!(ds.skipped[0].1.why.contains("leading out of the dataset"));
    let vd = &ds.variants[0];
    assert_eq!(
        (vd.variant.as_str(), vd.out.as_path()),
        ("camo", out.as_path())
    );
    let found: Vec<(u64, usize)> = vd
        .samples
        .iter()
        .map(|s| (s.index, s.files.len()))
        .collect();
    assert_eq!(found, [(3, 3), (4, 1)]);
    let s3 = &vd.samples[0];
    assert!(s3.has_pass(Pass::Mask) && s3.has_metadata() && !s3.has_pass(Pass::Depth));
    assert_eq!(
        s3.pass_path(Pass::Mask),
        s0.join(format!("{stem}_flat.png"))
    );
    assert!(!vd.samples[1].has_metadata());
    let skipped: Vec<String> = vd.skipped.iter().map(ToString::to_string).collect();
    assert_eq!(skipped.len(), 3, "{skipped:?}");
    assert!(skipped
        .iter()
        .any(|l| l.contains("_000004.json` is a symbolic link leading out")));
    assert!(skipped
        .iter()
        .any(|l| l.contains("_000003_depth_0001.png` is not a regular file")));
    assert!(skipped
        .iter()
        .any(|l| l.contains("is a folder named like a file")));
    // Metadata readers report the metadata's link, not the FIFO pass.
    assert_eq!(vd.skipped_for_metadata().count(), 1);
    assert_eq!(vd.temp_files.len(), 2);
    assert_eq!(vd.strays, [s0.join("notes.txt"), v.join("README")]);
    assert_eq!(vd.misplaced, [v.join(layout::metadata_file(&stem))]);
    assert_eq!(vd.manifests, [v.join("MANIFEST-0-8-0of1.json")]);
    assert!(vd.read_manifests()[0].1.is_err());
    let ledger = ds.read_ledger(&vd.ledgers[0]).unwrap();
    assert_eq!(ledger.len(), 1);
    assert_eq!(
        (ledger[0].index, ledger[0].error.as_str()),
        (Some(7), "boom")
    );
    assert_eq!(ds.read_metadata(s3).unwrap(), serde_json::json!({}));

    // The variant folder itself: its runs wrote into its parent.
    let one = Dataset::open(&v).unwrap();
    assert!(one.is_variant_dir);
    assert_eq!(one.variants[0].out, out);
    assert_eq!(one.variants[0].samples.len(), 2);
    assert!(matches!(
        Dataset::open(&s0.join("notes.txt")),
        Err(DatasetError::NotAFolder { .. })
    ));
}

#[test]
fn metadata_view_bounds_counts_and_names_file_and_key() {
    let good = serde_json::json!({
        "render": {"width": 4, "height": 2},
        "num_objects": 1,
        "visibility_threshold_px": 1,
        "objects": [{"visible_pixels": 3}],
        "image_index": 9,
        "passes": {"rgb": {}, "mask": {}, "nope": {}},
    });
    let v = MetadataView::of(&good, "m.json").unwrap();
    assert_eq!((v.width, v.height, v.num_objects), (4, 2, 1));
    assert_eq!(v.visible_pixels, [Some(3)]);
    assert_eq!(v.image_index, Some(9));
    assert_eq!(v.passes.len(), 2);
    assert_eq!(v.config_hash, None, "absent: not compared");
    let mut hashed = good.clone();
    hashed["config_hash"] = "00ff".into();
    assert_eq!(
        MetadataView::of(&hashed, "m.json")
            .unwrap()
            .config_hash
            .as_deref(),
        Some("00ff")
    );
    let bad = |patch: serde_json::Value| {
        let mut m = good.clone();
        for (k, val) in patch.as_object().unwrap() {
            m[k] = val.clone();
        }
        MetadataView::of(&m, "m.json").unwrap_err()
    };
    let e = bad(serde_json::json!({"render": {"width": "4", "height": 2}}));
    assert_eq!(
        (e.file.as_str(), e.key.as_str()),
        ("m.json", "render.width")
    );
    assert_eq!(
        e.to_string(),
        "metadata `m.json` key `render.width` is \"4\", not a whole number from 1 to 4096"
    );
    assert_eq!(
        bad(serde_json::json!({"render": {"width": 4, "height": 1u64 << 40}})).key,
        "render.height"
    );
    assert_eq!(
        bad(serde_json::json!({"num_objects": 1u64 << 62})).key,
        "num_objects"
    );
    assert_eq!(bad(serde_json::json!({"num_objects": 2})).key, "objects");
    assert_eq!(
        bad(serde_json::json!({"config_hash": 7})).key,
        "config_hash"
    );
    assert_eq!(bad(serde_json::json!({"objects": {"a": 1}})).key, "objects");
    assert_eq!(
        bad(serde_json::json!({"objects": [{"visible_pixels": 9}]})).key,
        "objects[0].visible_pixels"
    );
    assert_eq!(
        bad(serde_json::json!({"visibility_threshold_px": -1})).key,
        "visibility_threshold_px"
    );

    let stem = "CLEVRTEX_camo_000001";
    let meta = serde_json::json!({"image_filename": "CLEVRTEX_camo_000001.png", "split": "val"});
    assert_eq!(listed_passes(&meta, "m", stem).unwrap(), [Pass::Rgb]);
    assert_eq!(
        recorded_split(&meta["split"], "camo", "m").unwrap(),
        Some(layout::Split::Val)
    );
    // Absent, or the variant's name (the public generator's metadata): none recorded.
    assert_eq!(recorded_split(&Value::Null, "camo", "m").unwrap(), None);
    assert_eq!(recorded_split(&"camo".into(), "camo", "m").unwrap(), None);
    assert_eq!(
        recorded_split(&"full".into(), "camo", "m").unwrap_err().key,
        "split"
    );
    let e = listed_passes(
        &serde_json::json!({"mask_filename": "../../etc/passwd"}),
        "m",
        stem,
    )
    .unwrap_err();
    assert_eq!(e.key, "mask_filename");
    assert_eq!(
        recorded_split(&serde_json::json!(3), "camo", "m")
            .unwrap_err()
            .key,
        "split"
    );
}

#[test]
fn a_split_that_is_no_split_is_refused_by_every_reader() {
    let ours = serde_json::json!({
        "render": {"width": 4, "height": 3}, "num_objects": 0, "objects": [],
        "split": "../x",
    });
    let e = MetadataView::of(&ours, "m.json").unwrap_err().to_string();
    assert!(e.contains("split") && e.contains("../x"), "{e}");
    let published = serde_json::json!({"objects": [], "split": "../x"});
    let e = check_metadata(&published, "m.json")
        .unwrap_err()
        .to_string();
    assert!(e.contains("split") && e.contains("../x"), "{e}");
}

/// A bucket folder swapped for a link out of the dataset after the walk is not read
/// through (before, only the last component was checked: the Python `Dataset` and every
/// reader read the canary's file); links inside the dataset still are.
#[test]
fn a_folder_swapped_for_a_link_out_is_not_read_through() {
    let data = tempfile::tempdir().unwrap();
    let canary = tempfile::tempdir().unwrap();
    let v = data.path().join("clevrtex_camo");
    let bucket = v.join("0");
    std::fs::create_dir_all(&bucket).unwrap();
    let stem = layout::stem("camo", 0);
    let meta = layout::metadata_file(&stem);
    std::fs::write(bucket.join(&meta), b"{}").unwrap();
    std::fs::write(canary.path().join(&meta), b"secret").unwrap();
    let ds = Dataset::open(data.path()).unwrap();
    let s = &ds.variants[0].samples[0];
    assert_eq!(ds.read(&s.metadata_path(), 100).unwrap(), b"{}");
    // A link inside the dataset is followed.
    std::os::unix::fs::symlink("0", v.join("1")).unwrap();
    let inside = v.join("1").join(&meta);
    assert_eq!(read_beneath(&ds.root, &inside, 100).unwrap(), b"{}");
    // Swap the bucket for a link to the canary, after the walk.
    std::fs::rename(&bucket, v.join("moved")).unwrap();
    std::os::unix::fs::symlink(canary.path(), &bucket).unwrap();
    let got = read_beneath(&ds.root, &s.metadata_path(), 100);
    assert!(matches!(got, Err(ReadError::LeadsOut)), "{got:?}");
    assert!(ds.read(&s.metadata_path(), 100).is_err());
    // Relative links climbing out, and `..` in the path, are refused the same way.
    std::fs::remove_file(&bucket).unwrap();
    let up = format!("../../{}", canary.path().display());
    std::os::unix::fs::symlink(&up, &bucket).unwrap();
    let got = read_beneath(&ds.root, &s.metadata_path(), 100);
    assert!(matches!(got, Err(ReadError::LeadsOut)), "{got:?}");
    let dotdot = ds.root.join("..").join("x");
    assert!(matches!(
        read_beneath(&ds.root, &dotdot, 100),
        Err(ReadError::LeadsOut)
    ));
    // Given through a link to the root (the command line's path), the root is found.
    let alias_dir = tempfile::tempdir().unwrap();
    let alias = alias_dir.path().join("alias");
    std::os::unix::fs::symlink(&ds.root, &alias).unwrap();
    let via = alias.join("clevrtex_camo").join("moved").join(&meta);
    assert_eq!(read_beneath(&ds.root, &via, 100).unwrap(), b"{}");
}

#[test]
fn recorded_splits_win_and_unrecorded_ones_follow_the_position_rule() {
    use layout::Split::{Test, Train, Val};
    // A dataset grown in two runs of 10 (`--total` 10 each): what each run recorded.
    let mut grown: Vec<Option<layout::Split>> = Vec::new();
    for _run in 0..2 {
        grown.push(Some(Test));
        grown.push(Some(Val));
        grown.extend(std::iter::repeat_n(Some(Train), 8));
    }
    let s = splits("full", &grown);
    assert_eq!((s[1], s[2], s[11]), (Val, Train, Val));
    assert_eq!(split_sizes(&s), "test 2, val 2, train 16");
    // None recorded (the published ClevrTex): the public loader's positions.
    let s = splits("full", &[None; 20]);
    assert_eq!(split_sizes(&s), "test 2, val 2, train 16");
    assert_eq!((s[1], s[2], s[4]), (Test, Val, Train));
    assert_eq!(
        split_sizes(&splits("outd", &[None; 7])),
        "test 7, val 0, train 0"
    );
}
