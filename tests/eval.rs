//! Integration tests for `clevrtex eval`: the CLI on the fixtures of `tests/data/eval/` and
//! every error a user can meet. Metric values themselves are tested in `crates/eval/tests/`.

use std::path::Path;

use serde_json::Value;

use crate::util::{data, run, text};

fn copy_dir(from: &Path, to: &Path) {
    std::fs::create_dir_all(to).unwrap();
    for e in std::fs::read_dir(from).unwrap() {
        let p = e.unwrap().path();
        let dst = to.join(p.file_name().unwrap());
        if p.is_dir() {
            copy_dir(&p, &dst);
        } else {
            std::fs::copy(&p, &dst).unwrap();
        }
    }
}

fn s(p: &Path) -> &str {
    p.to_str().unwrap()
}

fn gt() -> std::path::PathBuf {
    data("eval/gt")
}

/// `clevrtex eval PREDS GT --split all --bootstrap 0 EXTRA --json JSON`: asserts success and
/// returns the JSON report.
fn eval_all_json(preds: &Path, extra: &[&str], json: &Path) -> Value {
    let gt = gt();
    let mut args = vec![
        "eval",
        s(preds),
        s(&gt),
        "--split",
        "all",
        "--bootstrap",
        "0",
    ];
    args.extend_from_slice(extra);
    args.extend_from_slice(&["--json", s(json)]);
    let out = run(&args);
    assert_eq!(out.status.code(), Some(0), "{}", text(&out));
    serde_json::from_slice(&std::fs::read(json).unwrap()).unwrap()
}

fn stderr(out: &std::process::Output) -> String {
    String::from_utf8_lossy(&out.stderr).into_owned()
}

/// A `.npy` file of `i32` labels.
fn npy_i32(shape: &[usize], values: &[i32]) -> Vec<u8> {
    let dims: Vec<String> = shape.iter().map(|d| format!("{d}, ")).collect();
    let mut header = format!(
        "{{'descr': '<i4', 'fortran_order': False, 'shape': ({}), }}",
        dims.concat()
    );
    while (10 + header.len() + 1) % 64 != 0 {
        header.push(' ');
    }
    header.push('\n');
    let mut b = b"\x93NUMPY\x01\x00".to_vec();
    b.extend((header.len() as u16).to_le_bytes());
    b.extend(header.as_bytes());
    for v in values {
        b.extend(v.to_le_bytes());
    }
    b
}

#[test]
fn eval_reports_table_json_and_csv() {
    let dir = tempfile::tempdir().unwrap();
    let json = dir.path().join("r.json");
    let csv = dir.path().join("r.csv");
    let preds = data("eval/preds/png");
    let out = run(&[
        "eval",
        s(&preds),
        s(&gt()),
        "--split",
        "all",
        "--json",
        s(&json),
        "--csv",
        s(&csv),
    ]);
    assert_eq!(out.status.code(), Some(0), "{}", text(&out));
    let stdout = String::from_utf8_lossy(&out.stdout);
    for name in [
        "mIoU_fg",
        "ARI_FG",
        "MSE",
        "95% CI",
        "by material",
        "by color",
        "by ground_material",
    ] {
        assert!(stdout.contains(name), "table lacks `{name}`:\n{stdout}");
    }
    let r: Value = serde_json::from_slice(&std::fs::read(&json).unwrap()).unwrap();
    let metrics = r["metrics"].as_object().unwrap();
    let names: Vec<&str> = metrics.keys().map(|k| k.as_str()).collect();
    let mut want = vec![
        "mIoU", "mIoU_fg", "mIoU_gt", "ARI", "ARI_FG", "MSE", "DICE", "DICE_fg", "acc", "mSC",
    ];
    want.sort();
    let mut names_sorted = names.clone();
    names_sorted.sort();
    assert_eq!(names_sorted, want);
    assert!(metrics
        .values()
        .all(|v| v.as_f64().is_some_and(f64::is_finite)));
    assert_eq!(r["counts"]["images"], 10);
    assert_eq!(r["counts"]["missing"], 0);
    assert_eq!(r["provenance"]["split"], "all");
    assert_eq!(r["provenance"]["protocol"], "clevrtex");
    assert_eq!(r["provenance"]["variant"], "vbg");
    assert_eq!(r["provenance"]["gt_hash_xxh3"].as_str().unwrap().len(), 16);
    let ci = r["ci95"]["ARI"].as_array().unwrap();
    let (lo, hi, mean) = (
        ci[0].as_f64().unwrap(),
        ci[1].as_f64().unwrap(),
        metrics["ARI"].as_f64().unwrap(),
    );
    assert!(lo <= mean && mean <= hi, "{lo} {mean} {hi}");
    assert!(r["breakdowns"]["material"]
        .as_object()
        .unwrap()
        .values()
        .all(|g| g["count"].as_u64().unwrap() > 0));

    let csv = std::fs::read_to_string(&csv).unwrap();
    let lines: Vec<&str> = csv.lines().collect();
    assert_eq!(lines.len(), 11);
    assert!(lines[0].starts_with("index,stem,mIoU,mIoU_fg,mIoU_gt,ARI,ARI_FG,MSE,DICE,DICE_fg,acc,mSC,true_segments,pred_segments,num_pairs"));
    assert!(lines[1].starts_with("0,CLEVRTEX_vbg_000000,"));

    // Same seed, same intervals; `--bootstrap 0` skips them.
    let json2 = dir.path().join("r2.json");
    let out = run(&[
        "eval",
        s(&preds),
        s(&gt()),
        "--split",
        "all",
        "--json",
        s(&json2),
    ]);
    assert_eq!(out.status.code(), Some(0), "{}", text(&out));
    let r2: Value = serde_json::from_slice(&std::fs::read(&json2).unwrap()).unwrap();
    assert_eq!(r["ci95"], r2["ci95"]);
    let r3 = eval_all_json(&preds, &[], &json2);
    assert!(r3["ci95"]["ARI"].is_null());
    assert_eq!(r3["metrics"], r["metrics"]);
}

#[test]
fn eval_npz_soft_masks_and_no_background() {
    let preds = data("eval/preds/npz");
    let dir = tempfile::tempdir().unwrap();
    let (a, b) = (dir.path().join("a.json"), dir.path().join("b.json"));
    let ra = eval_all_json(&preds, &[], &a);
    let rb = eval_all_json(&preds, &["--no-background"], &b);
    assert!(ra["metrics"]["MSE"].as_f64().unwrap() > 0.0);
    assert_ne!(ra["metrics"]["mIoU"], rb["metrics"]["mIoU"]);
    assert_eq!(rb["provenance"]["no_background"], true);
}

/// A ground-truth mask of another size than its own image: the ground truth is named, not the
/// prediction of the image's size (third hostile pass, issue 21).
#[test]
fn eval_names_a_ground_truth_mask_that_disagrees_with_its_image() {
    let dir = tempfile::tempdir().unwrap();
    let g = dir.path().join("gt");
    copy_dir(&gt(), &g);
    let preds = dir.path().join("preds");
    std::fs::create_dir_all(&preds).unwrap();
    for e in std::fs::read_dir(g.join("clevrtex_vbg/0")).unwrap() {
        let p = e.unwrap().path();
        let name = p.file_name().unwrap().to_str().unwrap().to_string();
        if let Some(stem) = name.strip_suffix("_flat.png") {
            std::fs::copy(&p, preds.join(format!("{stem}_mask.png"))).unwrap();
        }
    }
    let mask = g.join("clevrtex_vbg/0/CLEVRTEX_vbg_000003_flat.png");
    image::GrayImage::new(20, 15).save(&mask).unwrap();
    let out = run(&[
        "eval",
        s(&preds),
        s(&g),
        "--protocol",
        "native",
        "--split",
        "all",
    ]);
    assert_eq!(out.status.code(), Some(1), "{}", text(&out));
    let err = stderr(&out);
    assert!(
        err.contains("CLEVRTEX_vbg_000003_flat.png")
            && err.contains("the mask is 20x15 but its image is 40x30"),
        "{err}"
    );
    assert!(!err.contains("shape mismatch"), "{err}");
}

#[test]
fn eval_default_split_is_test() {
    let dir = tempfile::tempdir().unwrap();
    let j = dir.path().join("r.json");
    let out = run(&[
        "eval",
        s(&data("eval/preds/png")),
        s(&gt()),
        "--bootstrap",
        "0",
        "--json",
        s(&j),
    ]);
    assert_eq!(out.status.code(), Some(0), "{}", text(&out));
    let r: Value = serde_json::from_slice(&std::fs::read(&j).unwrap()).unwrap();
    assert_eq!(r["counts"]["images"], 1); // int(0.1 * 10)
    assert_eq!(r["provenance"]["split"], "test");
}

#[test]
fn eval_native_protocol_perfect_prediction() {
    // The ground-truth masks themselves, as predictions at native size, score 1.
    let dir = tempfile::tempdir().unwrap();
    for e in std::fs::read_dir(gt().join("clevrtex_vbg/0")).unwrap() {
        let p = e.unwrap().path();
        let name = p.file_name().unwrap().to_str().unwrap().to_string();
        if let Some(stem) = name.strip_suffix("_flat.png") {
            std::fs::copy(&p, dir.path().join(format!("{stem}_mask.png"))).unwrap();
        }
    }
    let j = dir.path().join("r.json");
    let out = run(&[
        "eval",
        s(dir.path()),
        s(&gt()),
        "--protocol",
        "native",
        "--split",
        "all",
        "--json",
        s(&j),
    ]);
    assert_eq!(out.status.code(), Some(0), "{}", text(&out));
    let r: Value = serde_json::from_slice(&std::fs::read(&j).unwrap()).unwrap();
    for m in ["mIoU", "mIoU_gt", "ARI", "ARI_FG", "DICE", "acc", "mSC"] {
        assert_eq!(r["metrics"][m].as_f64(), Some(1.0), "{m}");
    }
    assert!(
        r["metrics"]["MSE"].is_null(),
        "no reconstruction: MSE is not reported"
    );
    assert_eq!(r["counts"]["undefined"]["MSE"], 10);
    // The same masks under the default protocol have the wrong shape.
    let out = run(&["eval", s(dir.path()), s(&gt()), "--split", "all"]);
    assert_eq!(out.status.code(), Some(1), "{}", text(&out));
    let err = stderr(&out);
    assert!(
        err.contains("shape mismatch") && err.contains("(30, 40)") && err.contains("(128, 128)"),
        "{err}"
    );
    assert!(err.contains("hint:"), "{err}");
}

#[test]
fn eval_missing_predictions() {
    let dir = tempfile::tempdir().unwrap();
    copy_dir(&data("eval/preds/png"), dir.path());
    for i in [2, 4, 7] {
        std::fs::remove_file(dir.path().join(format!("CLEVRTEX_vbg_00000{i}_mask.png"))).unwrap();
    }
    let out = run(&["eval", s(dir.path()), s(&gt()), "--split", "all"]);
    assert_eq!(out.status.code(), Some(1), "{}", text(&out));
    let err = stderr(&out);
    assert!(err.contains("no prediction for 3 of 10"), "{err}");
    assert!(
        err.contains("`CLEVRTEX_vbg_000002`") && err.contains("--allow-missing"),
        "{err}"
    );

    let j = dir.path().join("r.json");
    let out = run(&[
        "eval",
        s(dir.path()),
        s(&gt()),
        "--split",
        "all",
        "--allow-missing",
        "--json",
        s(&j),
    ]);
    assert_eq!(out.status.code(), Some(0), "{}", text(&out));
    assert!(stderr(&out).contains("3 of 10 predictions were missing"));
    let r: Value = serde_json::from_slice(&std::fs::read(&j).unwrap()).unwrap();
    assert_eq!(r["counts"]["missing"], 3);
    assert_eq!(r["counts"]["undefined"]["MSE"], 3);
}

#[test]
fn eval_corrupt_and_unsupported_predictions() {
    let dir = tempfile::tempdir().unwrap();
    copy_dir(&data("eval/preds/npy"), dir.path());
    let bad = dir.path().join("CLEVRTEX_vbg_000001.npy");
    std::fs::write(&bad, b"\x93NUMPY garbage").unwrap();
    let out = run(&["eval", s(dir.path()), s(&gt()), "--split", "all"]);
    assert_eq!(out.status.code(), Some(1), "{}", text(&out));
    let err = stderr(&out);
    assert!(
        err.contains("CLEVRTEX_vbg_000001.npy") && err.contains("cannot decode"),
        "{err}"
    );
    // The hint says what a prediction must hold, not only which function writes it (third
    // hostile pass: an object-dtype array from `numpy.save` was told to use `numpy.save`).
    assert!(
        err.contains("segment ids (H, W)") && err.contains("no object dtype"),
        "{err}"
    );

    // Negative ids are refused with the value.
    std::fs::write(&bad, npy_i32(&[128, 128], &vec![-1; 128 * 128])).unwrap();
    let out = run(&["eval", s(dir.path()), s(&gt()), "--split", "all"]);
    assert_eq!(out.status.code(), Some(1), "{}", text(&out));
    assert!(stderr(&out).contains("segment id `-1`"), "{}", text(&out));

    // A wrong shape is named, never reshaped.
    std::fs::write(&bad, npy_i32(&[64, 256], &vec![0; 64 * 256])).unwrap();
    let out = run(&["eval", s(dir.path()), s(&gt()), "--split", "all"]);
    assert!(
        stderr(&out).contains("prediction is (64, 256), ground truth is (128, 128)"),
        "{}",
        text(&out)
    );

    // A 0-d array (issue 42): its shape is named, and the ground truth's is not made up from
    // it (it said "ground truth is (0, 128, 128)").
    std::fs::write(&bad, npy_i32(&[], &[5])).unwrap();
    let out = run(&["eval", s(dir.path()), s(&gt()), "--split", "all"]);
    assert_eq!(out.status.code(), Some(1), "{}", text(&out));
    assert!(
        stderr(&out).contains(
            "prediction is (), ground truth is (K, 128, 128) soft masks or (128, 128) segment ids"
        ),
        "{}",
        text(&out)
    );

    // An RGB PNG is not a segment-id mask.
    std::fs::remove_file(&bad).unwrap();
    std::fs::copy(
        data("eval/preds/png/CLEVRTEX_vbg_000001_recon.png"),
        dir.path().join("CLEVRTEX_vbg_000001_mask.png"),
    )
    .unwrap();
    let out = run(&["eval", s(dir.path()), s(&gt()), "--split", "all"]);
    assert_eq!(out.status.code(), Some(1), "{}", text(&out));
    assert!(
        stderr(&out).contains("must be greyscale or palette"),
        "{}",
        text(&out)
    );

    // Two predictions for one sample.
    std::fs::copy(data("eval/preds/npy/CLEVRTEX_vbg_000001.npy"), &bad).unwrap();
    let out = run(&["eval", s(dir.path()), s(&gt()), "--split", "all"]);
    assert_eq!(out.status.code(), Some(1), "{}", text(&out));
    assert!(
        stderr(&out).contains("duplicate prediction `CLEVRTEX_vbg_000001`"),
        "{}",
        text(&out)
    );
}

#[test]
fn eval_ground_truth_gaps_duplicates_and_holes() {
    let preds = data("eval/preds/png");
    let dir = tempfile::tempdir().unwrap();
    let g = dir.path().join("gt");
    copy_dir(&gt(), &g);
    let sample = g.join("clevrtex_vbg/0");

    // Duplicate: the same stem in two folders.
    std::fs::create_dir_all(g.join("clevrtex_vbg/extra")).unwrap();
    std::fs::copy(
        sample.join("CLEVRTEX_vbg_000003.png"),
        g.join("clevrtex_vbg/extra/CLEVRTEX_vbg_000003.png"),
    )
    .unwrap();
    let out = run(&["eval", s(&preds), s(&g), "--split", "all"]);
    assert_eq!(out.status.code(), Some(1), "{}", text(&out));
    assert!(
        stderr(&out).contains("duplicate ground-truth sample `CLEVRTEX_vbg_000003`"),
        "{}",
        text(&out)
    );
    std::fs::remove_dir_all(g.join("clevrtex_vbg/extra")).unwrap();

    // A sample without its mask.
    std::fs::rename(
        sample.join("CLEVRTEX_vbg_000004_flat.png"),
        dir.path().join("x.png"),
    )
    .unwrap();
    let out = run(&["eval", s(&preds), s(&g), "--split", "all"]);
    assert!(
        stderr(&out).contains("`CLEVRTEX_vbg_000004` has no") && stderr(&out).contains("_flat.png"),
        "{}",
        text(&out)
    );
    std::fs::rename(
        dir.path().join("x.png"),
        sample.join("CLEVRTEX_vbg_000004_flat.png"),
    )
    .unwrap();

    // A corrupt ground-truth mask is named.
    std::fs::write(sample.join("CLEVRTEX_vbg_000002_flat.png"), b"not a png").unwrap();
    let out = run(&["eval", s(&preds), s(&g), "--split", "all"]);
    assert_eq!(out.status.code(), Some(1), "{}", text(&out));
    assert!(
        stderr(&out).contains("CLEVRTEX_vbg_000002_flat.png")
            && stderr(&out).contains("not a valid PNG"),
        "{}",
        text(&out)
    );

    // A gap in the index sequence: a sample absent (a sample with only its image missing is
    // named instead: `eval_names_a_ground_truth_sample_without_its_image`).
    for f in [
        "CLEVRTEX_vbg_000005.png",
        "CLEVRTEX_vbg_000005_flat.png",
        "CLEVRTEX_vbg_000005.json",
    ] {
        std::fs::remove_file(sample.join(f)).unwrap();
    }
    let out = run(&["eval", s(&preds), s(&g), "--split", "all"]);
    assert_eq!(out.status.code(), Some(1), "{}", text(&out));
    assert!(
        stderr(&out).contains("gap: index `5` is missing"),
        "{}",
        text(&out)
    );
}

/// Ground-truth metadata goes through the dataset reader's check, as in `preview`, `report`,
/// `export` and the Python `Dataset`: a count that disagrees with the object list is named.
#[test]
fn eval_names_ground_truth_metadata_the_dataset_reader_rejects() {
    let preds = data("eval/preds/png");
    let dir = tempfile::tempdir().unwrap();
    let g = dir.path().join("gt");
    copy_dir(&gt(), &g);
    let meta_path = g.join("clevrtex_vbg/0/CLEVRTEX_vbg_000001.json");
    let mut meta: Value = serde_json::from_slice(&std::fs::read(&meta_path).unwrap()).unwrap();
    let n = meta["objects"].as_array().unwrap().len();
    meta["num_objects"] = (n + 1).into();
    std::fs::write(&meta_path, meta.to_string()).unwrap();
    let out = run(&["eval", s(&preds), s(&g), "--split", "all"]);
    assert_eq!(out.status.code(), Some(1), "{}", text(&out));
    let e = stderr(&out);
    assert!(
        e.contains("CLEVRTEX_vbg_000001.json")
            && e.contains(&format!(
                "key `objects` has {n} entries but `num_objects` is {}",
                n + 1
            )),
        "{}",
        text(&out)
    );
}

#[test]
fn eval_variant_and_split_errors() {
    let preds = data("eval/preds/png");
    let out = run(&["eval", s(&preds), s(&gt()), "--variant", "camo"]);
    assert_eq!(out.status.code(), Some(1), "{}", text(&out));
    assert!(
        stderr(&out).contains("no ground-truth samples `CLEVRTEX_camo_??????.png`"),
        "{}",
        text(&out)
    );

    let dir = tempfile::tempdir().unwrap();
    let out = run(&["eval", s(&preds), s(&dir.path().join("nope"))]);
    assert_eq!(out.status.code(), Some(1), "{}", text(&out));
    assert!(stderr(&out).contains("cannot read"), "{}", text(&out));

    // Two variants side by side: the user must pick one.
    let two = dir.path().join("two");
    copy_dir(&gt(), &two);
    std::fs::create_dir_all(two.join("clevrtex_camo/0")).unwrap();
    std::fs::copy(
        gt().join("clevrtex_vbg/0/CLEVRTEX_vbg_000000.png"),
        two.join("clevrtex_camo/0/CLEVRTEX_camo_000000.png"),
    )
    .unwrap();
    let out = run(&["eval", s(&preds), s(&two)]);
    assert_eq!(out.status.code(), Some(1), "{}", text(&out));
    assert!(
        stderr(&out).contains("several variants: `camo`, `vbg`")
            && stderr(&out).contains("--variant"),
        "{}",
        text(&out)
    );

    let out = run(&["eval", s(&preds), s(&gt()), "--split", "sideways"]);
    assert_eq!(out.status.code(), Some(2), "{}", text(&out));
}

#[test]
fn eval_outd_is_test_only() {
    // The fixture renamed to `outd`: its default split is all of it, and `val` is a usage error.
    let dir = tempfile::tempdir().unwrap();
    let (g, p) = (
        dir.path().join("gt/clevrtex_outd/0"),
        dir.path().join("preds"),
    );
    std::fs::create_dir_all(&g).unwrap();
    std::fs::create_dir_all(&p).unwrap();
    for (from, to) in [
        (gt().join("clevrtex_vbg/0"), &g),
        (data("eval/preds/png"), &p),
    ] {
        for e in std::fs::read_dir(from).unwrap() {
            let f = e.unwrap().path();
            let name = f
                .file_name()
                .unwrap()
                .to_str()
                .unwrap()
                .replace("_vbg_", "_outd_");
            std::fs::copy(&f, to.join(name)).unwrap();
        }
    }
    let j = dir.path().join("r.json");
    let out = run(&[
        "eval",
        s(&p),
        s(&dir.path().join("gt")),
        "--bootstrap",
        "0",
        "--json",
        s(&j),
    ]);
    assert_eq!(out.status.code(), Some(0), "{}", text(&out));
    let r: Value = serde_json::from_slice(&std::fs::read(&j).unwrap()).unwrap();
    assert_eq!(r["counts"]["images"], 10);
    assert_eq!(r["provenance"]["variant"], "outd");
    let out = run(&["eval", s(&p), s(&dir.path().join("gt")), "--split", "val"]);
    assert_eq!(out.status.code(), Some(1), "{}", text(&out));
    assert!(
        stderr(&out).contains("`outd` is a test-only dataset"),
        "{}",
        text(&out)
    );
}

/// End to end on a dataset made by `clevrtex generate` with the real Blender: the ground-truth
/// masks with their labels permuted score perfectly, the image itself as a reconstruction has
/// zero error, and an all-background prediction scores what it should.
#[test]
fn eval_scores_a_real_generated_dataset() {
    let Some(blender) = crate::util::blender_or_skip("eval_scores_a_real_generated_dataset") else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let gt = dir.path().join("gt");
    let out = crate::util::clevrtex()
        .args(["generate", "--variant", "full", "-n", "2", "--seed", "1"])
        .args(["--width", "64", "--height", "48", "--samples", "1"])
        .arg("--blender")
        .arg(&blender)
        .arg("--out")
        .arg(&gt)
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(0), "{}", text(&out));

    let perm = dir.path().join("perm");
    let zero = dir.path().join("zero");
    std::fs::create_dir_all(&perm).unwrap();
    std::fs::create_dir_all(&zero).unwrap();
    let mut stems = Vec::new();
    for e in std::fs::read_dir(gt.join("clevrtex_full/0")).unwrap() {
        let p = e.unwrap().path();
        let name = p.file_name().unwrap().to_str().unwrap().to_string();
        let Some(stem) = name.strip_suffix("_flat.png") else {
            continue;
        };
        let mask = clevrtex_eval::read::png_labels(&std::fs::read(&p).unwrap()).unwrap();
        let shape = [mask.height, mask.width];
        // A relabelling that moves the background too: id -> (id * 7 + 3) % 11 on 0..=10.
        let permuted: Vec<i32> = mask
            .labels
            .iter()
            .map(|&v| ((v * 7 + 3) % 11) as i32)
            .collect();
        assert!(mask.labels.iter().all(|&v| v <= 10), "{name}: ids above 10");
        std::fs::write(perm.join(format!("{stem}.npy")), npy_i32(&shape, &permuted)).unwrap();
        std::fs::copy(
            gt.join(format!("clevrtex_full/0/{stem}.png")),
            perm.join(format!("{stem}_recon.png")),
        )
        .unwrap();
        let zeros = vec![0; mask.labels.len()];
        std::fs::write(zero.join(format!("{stem}.npy")), npy_i32(&shape, &zeros)).unwrap();
        stems.push(stem.to_string());
    }
    assert_eq!(stems.len(), 2);

    let eval = |preds: &Path, name: &str| -> (Value, String) {
        let j = dir.path().join(format!("{name}.json"));
        let c = dir.path().join(format!("{name}.csv"));
        let out = run(&[
            "eval",
            s(preds),
            s(&gt),
            "--protocol",
            "native",
            "--split",
            "all",
            "--json",
            s(&j),
            "--csv",
            s(&c),
        ]);
        assert_eq!(out.status.code(), Some(0), "{}", text(&out));
        let r: Value = serde_json::from_slice(&std::fs::read(&j).unwrap()).unwrap();
        (r, std::fs::read_to_string(&c).unwrap())
    };

    let (r, csv) = eval(&perm, "perm");
    for m in [
        "mIoU", "mIoU_fg", "mIoU_gt", "ARI", "ARI_FG", "DICE", "DICE_fg", "acc", "mSC",
    ] {
        assert_eq!(r["metrics"][m].as_f64(), Some(1.0), "{m}: {r}");
    }
    assert_eq!(r["metrics"]["MSE"].as_f64(), Some(0.0), "{r}");
    assert_eq!(r["counts"]["images"], 2);
    assert_eq!(r["counts"]["missing"], 0);
    assert_eq!(csv.lines().count(), 3, "{csv}");
    for stem in &stems {
        assert!(csv.contains(stem.as_str()), "{csv}");
    }
    // The breakdown covers every object of the metadata.
    let objects: u64 = r["breakdowns"]["shape"]
        .as_object()
        .unwrap()
        .values()
        .map(|g| g["count"].as_u64().unwrap())
        .sum();
    let expected: u64 = stems
        .iter()
        .map(|stem| {
            let meta: Value = serde_json::from_slice(
                &std::fs::read(gt.join(format!("clevrtex_full/0/{stem}.json"))).unwrap(),
            )
            .unwrap();
            meta["objects"].as_array().unwrap().len() as u64
        })
        .sum();
    assert_eq!(objects, expected, "{r}");

    let (r, _) = eval(&zero, "zero");
    for m in ["mIoU_fg", "ARI", "ARI_FG", "DICE_fg", "acc"] {
        assert_eq!(r["metrics"][m].as_f64(), Some(0.0), "{m}: {r}");
    }
    let miou = r["metrics"]["mIoU"].as_f64().unwrap();
    assert!(miou > 0.0 && miou < 0.5, "only the background matches: {r}");
}

/// I/O errors name the path and their cause once, before the `hint:` line, which ends the
/// message; a report that cannot be written leaves no temporary file.
#[test]
fn eval_io_errors_name_the_cause_once_before_the_hint() {
    let dir = tempfile::tempdir().unwrap();
    let check = |args: &[&str], first: &str, cause: &str| {
        let out = run(args);
        assert_eq!(out.status.code(), Some(1), "{}", text(&out));
        let err = stderr(&out);
        let lines: Vec<&str> = err.trim_end().lines().collect();
        assert_eq!(lines.len(), 2, "{err}");
        assert!(lines[0].starts_with(first), "expected `{first}`:\n{err}");
        assert!(lines[0].contains(cause), "expected `{cause}`:\n{err}");
        assert!(lines[1].starts_with("hint:"), "{err}");
        assert!(
            !lines[1].contains(cause),
            "the cause is repeated after the hint:\n{err}"
        );
    };
    let nowhere = dir.path().join("nowhere");
    let file = dir.path().join("a-file");
    std::fs::write(&file, "x").unwrap();
    let preds = data("eval/preds/png");
    check(
        &["eval", s(&nowhere), s(&gt()), "--split", "all"],
        "error: cannot read `",
        "no such directory",
    );
    check(
        &["eval", s(&preds), s(&file), "--split", "all"],
        "error: cannot read `",
        "not a directory",
    );
    // `--json` naming a directory: the rename fails after the temporary was written.
    let target = dir.path().join("taken");
    std::fs::create_dir(&target).unwrap();
    check(
        &[
            "eval",
            s(&preds),
            s(&gt()),
            "--split",
            "all",
            "--bootstrap",
            "0",
            "--json",
            s(&target),
        ],
        "error: cannot write `",
        "os error",
    );
    let left: Vec<_> = std::fs::read_dir(dir.path())
        .unwrap()
        .map(|e| e.unwrap().file_name().into_string().unwrap())
        .collect();
    assert!(
        left.iter().all(|n| !n.ends_with(".tmp")),
        "a temporary file was left: {left:?}"
    );
}

/// A `.npy` header for `descr` and `shape` (the data follows it).
fn npy_header(descr: &str, shape: &[usize]) -> Vec<u8> {
    let dims: Vec<String> = shape.iter().map(|d| format!("{d}, ")).collect();
    let mut header = format!(
        "{{'descr': '{descr}', 'fortran_order': False, 'shape': ({}), }}",
        dims.concat()
    );
    while (10 + header.len() + 1) % 64 != 0 {
        header.push(' ');
    }
    header.push('\n');
    let mut b = b"\x93NUMPY\x01\x00".to_vec();
    b.extend((header.len() as u16).to_le_bytes());
    b.extend(header.as_bytes());
    b
}

/// Write an `.npz` of `(name, npy bytes, extra zero bytes after them)` members, deflated.
fn write_npz(path: &Path, members: &[(&str, Vec<u8>, usize)]) {
    use std::io::Write;
    let mut z = zip::ZipWriter::new(std::fs::File::create(path).unwrap());
    let opts = zip::write::SimpleFileOptions::default()
        .compression_method(zip::CompressionMethod::Deflated)
        .large_file(true);
    for (name, bytes, zeros) in members {
        z.start_file(format!("{name}.npy"), opts).unwrap();
        z.write_all(bytes).unwrap();
        let chunk = vec![0u8; 1 << 20];
        let mut left = *zeros;
        while left > 0 {
            let n = left.min(chunk.len());
            z.write_all(&chunk[..n]).unwrap();
            left -= n;
        }
    }
    z.finish().unwrap();
}

/// A copy of the npz predictions of the fixture, to spoil one of.
fn npz_preds(dir: &Path) -> std::path::PathBuf {
    let preds = dir.join("preds");
    copy_dir(&data("eval/preds/npz"), &preds);
    preds
}

#[test]
fn eval_bootstrap_above_the_cap_is_refused_at_once() {
    let t = std::time::Instant::now();
    let out = run(&[
        "eval",
        s(&data("eval/preds/png")),
        s(&gt()),
        "--bootstrap",
        "1000000000",
    ]);
    assert_eq!(out.status.code(), Some(1), "{}", text(&out));
    assert!(
        stderr(&out).contains("`--bootstrap 1000000000` is more than the 100000"),
        "{}",
        text(&out)
    );
    assert!(t.elapsed() < std::time::Duration::from_secs(30));
}

/// A 256 MiB `masks` member that deflates to a few hundred KB, declaring far more masks than
/// a 40x30 image can have: refused from its header, before its data is inflated.
#[test]
fn eval_npz_bomb_is_rejected_from_its_header() {
    let dir = tempfile::tempdir().unwrap();
    let preds = npz_preds(dir.path());
    let shape = [55_924, 30, 40];
    let bomb = preds.join("clevrtex_vbg/0/CLEVRTEX_vbg_000000.npz");
    let _ = std::fs::remove_file(&bomb);
    let bomb = preds.join("CLEVRTEX_vbg_000000.npz");
    write_npz(
        &bomb,
        &[("masks", npy_header("<f4", &shape), 55_924 * 1200 * 4)],
    );
    assert!(std::fs::metadata(&bomb).unwrap().len() < 4 << 20);
    let out = run(&[
        "eval",
        s(&preds),
        s(&gt()),
        "--split",
        "all",
        "--bootstrap",
        "0",
    ]);
    assert_eq!(out.status.code(), Some(1), "{}", text(&out));
    assert!(
        stderr(&out).contains("declares shape [55924, 30, 40] (67108800 values), more than the"),
        "{}",
        text(&out)
    );
}

#[test]
fn eval_empty_default_split_is_an_error_not_a_usage_error() {
    let dir = tempfile::tempdir().unwrap();
    let small = dir.path().join("gt");
    copy_dir(&gt(), &small);
    for i in 5..10 {
        for suffix in [".png", "_flat.png", ".json"] {
            let f = small.join(format!("clevrtex_vbg/0/CLEVRTEX_vbg_00000{i}{suffix}"));
            std::fs::remove_file(f).unwrap();
        }
    }
    let out = run(&[
        "eval",
        s(&data("eval/preds/png")),
        s(&small),
        "--bootstrap",
        "0",
    ]);
    assert_eq!(out.status.code(), Some(1), "{}", text(&out));
    assert!(
        stderr(&out).contains("the `test` split of")
            && stderr(&out).contains("is empty: it has 5 samples in all (test 0, val 1, train 4)")
            && stderr(&out).contains("--split all"),
        "{}",
        text(&out)
    );
}

#[test]
fn eval_uint64_ids_too_large_are_named_as_they_are() {
    let dir = tempfile::tempdir().unwrap();
    let preds = dir.path().join("preds");
    std::fs::create_dir_all(&preds).unwrap();
    let mut b = npy_header("<u8", &[30, 40]);
    for i in 0..1200u64 {
        b.extend(if i == 7 { u64::MAX } else { 0 }.to_le_bytes());
    }
    std::fs::write(preds.join("CLEVRTEX_vbg_000000.npy"), b).unwrap();
    let out = run(&["eval", s(&preds), s(&gt()), "--bootstrap", "0"]);
    assert_eq!(out.status.code(), Some(1), "{}", text(&out));
    assert!(
        stderr(&out).contains("value 18446744073709551615 of `<u8` is too large"),
        "{}",
        text(&out)
    );
    assert!(
        !stderr(&out).contains("9223372036854775807"),
        "{}",
        text(&out)
    );
}

/// NaN, 1e30 and out-of-range reconstructions: MSE undefined (said, counted, left out of the
/// mean), or scored as given with a warning.
#[test]
fn eval_nan_huge_and_out_of_range_reconstructions_are_reported() {
    let dir = tempfile::tempdir().unwrap();
    let preds = npz_preds(dir.path());
    // The evaluation shape under `--protocol clevrtex` (the default): 128x128.
    let labels = npy_i32(&[128, 128], &[0; 128 * 128]);
    let recon = |v: f32| {
        let mut b = npy_header("<f4", &[3, 128, 128]);
        for _ in 0..3 * 128 * 128 {
            b.extend(v.to_le_bytes());
        }
        b
    };
    for (i, v) in [(0, f32::NAN), (1, 1e30), (2, 1.5)] {
        let f = preds.join(format!("CLEVRTEX_vbg_00000{i}.npz"));
        let _ = std::fs::remove_file(&f);
        write_npz(&f, &[("labels", labels.clone(), 0), ("recon", recon(v), 0)]);
    }
    let j = dir.path().join("r.json");
    let out = run(&[
        "eval",
        s(&preds),
        s(&gt()),
        "--split",
        "all",
        "--bootstrap",
        "0",
        "--json",
        s(&j),
    ]);
    assert_eq!(out.status.code(), Some(0), "{}", text(&out));
    let r: Value = serde_json::from_slice(&std::fs::read(&j).unwrap()).unwrap();
    assert_eq!(r["counts"]["recon_undefined"], 2, "{r}");
    assert_eq!(r["counts"]["recon_out_of_range"], 1, "{r}");
    assert!(r["metrics"]["MSE"].as_f64().unwrap().is_finite());
    let err = stderr(&out);
    assert!(
        err.contains("2 of 10 reconstructions hold NaN or infinite values")
            && err.contains("1 of 10 reconstructions hold values outside [0, 1]"),
        "{}",
        text(&out)
    );
}

/// Write a valid greyscale PNG of `side` x `side` zeros (under 1 MB for 30000): a small file
/// that decodes to gigabytes. False when python3 cannot write it.
fn write_zero_png(path: &Path, side: u32) -> bool {
    std::process::Command::new("python3")
        .arg("-c")
        .arg(
            "import struct, sys, zlib\n\
             w = h = int(sys.argv[2])\n\
             def chunk(t, d):\n\
             \x20   return struct.pack('>I', len(d)) + t + d + struct.pack('>I', zlib.crc32(t + d) & 0xffffffff)\n\
             z = zlib.compressobj(9)\n\
             row = bytes(w + 1)\n\
             data = b''.join(z.compress(row) for _ in range(h)) + z.flush()\n\
             png = b'\\x89PNG\\r\\n\\x1a\\n' + chunk(b'IHDR', struct.pack('>IIBBBBB', w, h, 8, 0, 0, 0, 0)) + chunk(b'IDAT', data) + chunk(b'IEND', b'')\n\
             open(sys.argv[1], 'wb').write(png)\n",
        )
        .arg(path)
        .arg(side.to_string())
        .status()
        .is_ok_and(|s| s.success())
}

/// A 30000x30000 `_mask.png` of zeros (about 1 MB deflated) against the dataset's 40x30: its
/// size is refused from the PNG header, before anything is decoded. Before, `--native-size`
/// decoded it first (0.9 GB of pixels, 3.6 GB of ids: 4.4 GB seen), here an abort under a
/// 2 GB address-space limit.
#[test]
fn eval_native_size_refuses_a_huge_png_from_its_header() {
    let dir = tempfile::tempdir().unwrap();
    // The ground truth's own masks as native-size predictions, one of them replaced.
    let preds = dir.path().join("preds");
    std::fs::create_dir_all(&preds).unwrap();
    for e in std::fs::read_dir(gt().join("clevrtex_vbg/0")).unwrap() {
        let p = e.unwrap().path();
        let name = p.file_name().unwrap().to_str().unwrap().to_string();
        if let Some(stem) = name.strip_suffix("_flat.png") {
            std::fs::copy(&p, preds.join(format!("{stem}_mask.png"))).unwrap();
        }
    }
    let target = preds.join("CLEVRTEX_vbg_000000_mask.png");
    let made = write_zero_png(&target, 30000);
    if !made {
        crate::util::skip(
            "eval_native_size_refuses_a_huge_png_from_its_header",
            crate::util::REQUIRE_TOOLS,
            "python3 could not write the test PNG",
            "install Python 3",
        );
        return;
    }
    assert!(std::fs::metadata(&target).unwrap().len() < 2 << 20);
    let (p, g) = (preds.clone(), gt());
    let mut args = vec![std::ffi::OsStr::new("eval"), p.as_os_str(), g.as_os_str()];
    args.extend(
        ["--native-size", "--split", "all", "--bootstrap", "0"]
            .iter()
            .map(std::ffi::OsStr::new),
    );
    let (code, t) = crate::util::run_limited(&args, &[], 120);
    assert_eq!(code, Some(1), "{t}");
    assert!(
        t.contains("30000"),
        "the message gives the declared size: {t}"
    );
}

/// An `.npz` with 3,001 arrays and neither `labels` nor `masks`: the error lists ten names and
/// how many more, not all 3,001 (it did).
#[test]
fn eval_npz_without_labels_lists_a_few_of_its_names() {
    let dir = tempfile::tempdir().unwrap();
    let preds = npz_preds(dir.path());
    let spoilt = preds.join("clevrtex_vbg/0/CLEVRTEX_vbg_000000.npz");
    let _ = std::fs::remove_file(&spoilt);
    let spoilt = preds.join("CLEVRTEX_vbg_000000.npz");
    let names: Vec<String> = (0..3001).map(|i| format!("junk{i}")).collect();
    let members: Vec<(&str, Vec<u8>, usize)> = names
        .iter()
        .map(|n| (n.as_str(), npy_header("<f4", &[1]), 4))
        .collect();
    write_npz(&spoilt, &members);
    let out = run(&[
        "eval",
        s(&preds),
        s(&gt()),
        "--split",
        "all",
        "--bootstrap",
        "0",
    ]);
    let err = stderr(&out);
    assert_eq!(out.status.code(), Some(1), "{}", text(&out));
    assert!(err.contains("and 2991 more"), "{err}");
    assert!(!err.contains("junk2999"), "{err}");
}

/// A prediction that is a link out of the predictions folder is not followed (even to a
/// valid prediction), and a FIFO is never opened: both count as missing, named, and eval
/// exits 1 without hanging. Before, the link was followed and scored.
#[test]
fn eval_follows_no_link_out_of_its_folders_and_opens_no_fifo() {
    let dir = tempfile::tempdir().unwrap();
    let preds = dir.path().join("preds");
    copy_dir(&data("eval/preds/png"), &preds);
    let mut masks: Vec<std::path::PathBuf> = std::fs::read_dir(&preds)
        .unwrap()
        .flatten()
        .map(|e| e.path())
        .filter(|p| p.to_string_lossy().ends_with("_mask.png"))
        .collect();
    masks.sort();
    // The first prediction moves out of the folder and is linked back.
    let outside = dir.path().join("outside.png");
    std::fs::rename(&masks[0], &outside).unwrap();
    std::os::unix::fs::symlink(&outside, &masks[0]).unwrap();
    let g = gt();
    let mut args = vec![
        std::ffi::OsStr::new("eval"),
        preds.as_os_str(),
        g.as_os_str(),
    ];
    args.extend(
        ["--split", "all", "--bootstrap", "0"]
            .iter()
            .map(std::ffi::OsStr::new),
    );
    let o = crate::util::run_within(&args, 60);
    let t = text(&o);
    assert_eq!(
        o.status.code(),
        Some(1),
        "the linked prediction is not scored: {t}"
    );
    let stem = masks[0]
        .file_name()
        .unwrap()
        .to_string_lossy()
        .replace("_mask.png", "");
    assert!(t.contains(&stem), "the missing prediction is named: {t}");
    // ... and the file that was found but not read, with why (third hostile pass, issue 21).
    let file = format!("{stem}_mask.png` ");
    assert!(t.contains("not read: `") && t.contains(&file), "{t}");
    // A FIFO in its place: missing too, and no hang.
    std::fs::remove_file(&masks[0]).unwrap();
    let st = std::process::Command::new("mkfifo")
        .arg(&masks[0])
        .status()
        .unwrap();
    assert!(st.success());
    let o = crate::util::run_within(&args, 60);
    let t = text(&o);
    assert_eq!(o.status.code(), Some(1), "{t}");
    assert!(t.contains(&stem), "{t}");
    assert!(t.contains(&file) && t.contains("FIFO"), "{t}");
}

/// A ground-truth sample's mask (or metadata) beside its image is read only if the walk of
/// the ground-truth folder found it: a mask that is a link out of the folder is refused by
/// name (it was followed and scored), a metadata FIFO is called what it is (it was "missing").
#[test]
fn eval_refuses_a_ground_truth_mask_linked_out_of_its_folder() {
    let dir = tempfile::tempdir().unwrap();
    let g = dir.path().join("gt");
    copy_dir(&gt(), &g);
    let sub = g.join("clevrtex_vbg/0");
    let mask = sub.join("CLEVRTEX_vbg_000003_flat.png");
    let outside = dir.path().join("outside_flat.png");
    std::fs::rename(&mask, &outside).unwrap();
    std::os::unix::fs::symlink(&outside, &mask).unwrap();
    let preds = data("eval/preds/png");
    let args: Vec<&std::ffi::OsStr> = vec![
        "eval".as_ref(),
        preds.as_os_str(),
        g.as_os_str(),
        "--split".as_ref(),
        "all".as_ref(),
        "--bootstrap".as_ref(),
        "0".as_ref(),
    ];
    let o = crate::util::run_within(&args, 60);
    let t = text(&o);
    assert_eq!(o.status.code(), Some(1), "{t}");
    assert!(
        t.contains("CLEVRTEX_vbg_000003_flat.png` is a symbolic link leading out"),
        "{t}"
    );
    assert!(t.contains("hint: "), "{t}");
    // A FIFO in the metadata's place: named as not a regular file, and no hang.
    std::fs::remove_file(&mask).unwrap();
    std::fs::rename(&outside, &mask).unwrap();
    let meta = sub.join("CLEVRTEX_vbg_000003.json");
    std::fs::remove_file(&meta).unwrap();
    let st = std::process::Command::new("mkfifo")
        .arg(&meta)
        .status()
        .unwrap();
    assert!(st.success());
    let o = crate::util::run_within(&args, 60);
    let t = text(&o);
    assert_eq!(o.status.code(), Some(1), "{t}");
    assert!(
        t.contains("CLEVRTEX_vbg_000003.json` is not a regular file"),
        "{t}"
    );
}

/// A ground-truth mask whose header declares 30000x30000 pixels (a valid PNG of zeros under
/// 1 MB) is refused from its header before it is decoded, with or without `--native-size`:
/// decoding it cost 0.9 GB of pixels and 3.6 GB of labels (an abort under a memory limit).
/// Ground-truth metadata is read up to 64 MiB (it was read up to 1 GiB and parsed).
#[test]
fn eval_checks_a_ground_truth_png_size_from_its_header() {
    let dir = tempfile::tempdir().unwrap();
    let g = dir.path().join("gt");
    copy_dir(&gt(), &g);
    let target = g.join("clevrtex_vbg/0/CLEVRTEX_vbg_000000_flat.png");
    if !write_zero_png(&target, 30000) {
        crate::util::skip(
            "eval_checks_a_ground_truth_png_size_from_its_header",
            crate::util::REQUIRE_TOOLS,
            "python3 could not write the test PNG",
            "install Python 3",
        );
        return;
    }
    assert!(std::fs::metadata(&target).unwrap().len() < 2 << 20);
    let preds = data("eval/preds/png");
    // Native-size predictions: the ground truth's own masks, so that only the huge mask fails.
    let native = dir.path().join("native");
    std::fs::create_dir_all(&native).unwrap();
    for e in std::fs::read_dir(gt().join("clevrtex_vbg/0")).unwrap() {
        let p = e.unwrap().path();
        let name = p.file_name().unwrap().to_str().unwrap().to_string();
        if let Some(stem) = name.strip_suffix("_flat.png") {
            std::fs::copy(&p, native.join(format!("{stem}_mask.png"))).unwrap();
        }
    }
    for (p, extra) in [(&preds, &[][..]), (&native, &["--native-size"][..])] {
        let mut args = vec![std::ffi::OsStr::new("eval"), p.as_os_str(), g.as_os_str()];
        args.extend(
            ["--split", "all", "--bootstrap", "0"]
                .iter()
                .chain(extra)
                .map(std::ffi::OsStr::new),
        );
        let (code, t) = crate::util::run_limited(&args, &[], 120);
        assert_eq!(code, Some(1), "{extra:?}: {t}");
        assert!(
            t.contains("CLEVRTEX_vbg_000000_flat.png") && t.contains("declares 30000x30000"),
            "{extra:?}: {t}"
        );
    }
    // Metadata over 64 MiB (sparse: no disk) is refused by its size, not read and parsed.
    std::fs::copy(
        gt().join("clevrtex_vbg/0/CLEVRTEX_vbg_000000_flat.png"),
        &target,
    )
    .unwrap();
    let meta = g.join("clevrtex_vbg/0/CLEVRTEX_vbg_000001.json");
    std::fs::OpenOptions::new()
        .write(true)
        .open(&meta)
        .unwrap()
        .set_len((64 << 20) + 1)
        .unwrap();
    let o = crate::util::run_within(
        &[
            "eval".as_ref(),
            preds.as_os_str(),
            g.as_os_str(),
            "--split".as_ref(),
            "all".as_ref(),
            "--bootstrap".as_ref(),
            "0".as_ref(),
        ],
        60,
    );
    let t = text(&o);
    assert_eq!(o.status.code(), Some(1), "{t}");
    assert!(
        t.contains("CLEVRTEX_vbg_000001.json") && t.contains("over the 67108864 bytes"),
        "{t}"
    );
}

/// A variant whose objects are plain-coloured (`objects_plain_coloured` in its config: `vbg`
/// and `clevr`) is broken down by colour; `clevr` was not (only `vbg` by name).
#[test]
fn eval_breaks_clevr_down_by_colour() {
    let dir = tempfile::tempdir().unwrap();
    let (gt, preds) = (dir.path().join("gt"), dir.path().join("preds"));
    let sub = gt.join("clevrtex_clevr/0");
    std::fs::create_dir_all(&sub).unwrap();
    std::fs::create_dir_all(&preds).unwrap();
    let stem = "CLEVRTEX_clevr_000000";
    let meta = serde_json::json!({
        "image_index": 0, "split": "test", "num_objects": 1, "ground_material": "plain",
        "objects": [{"color": "red", "material": "rubber", "shape": "cube", "size": "large"}],
    });
    std::fs::write(sub.join(format!("{stem}.json")), meta.to_string()).unwrap();
    image::RgbImage::from_pixel(16, 12, image::Rgb([90, 120, 150]))
        .save(sub.join(format!("{stem}.png")))
        .unwrap();
    // The object covers the left half.
    let mask = image::GrayImage::from_fn(16, 12, |x, _| image::Luma([u8::from(x < 8)]));
    mask.save(sub.join(format!("{stem}_flat.png"))).unwrap();
    mask.save(preds.join(format!("{stem}_mask.png"))).unwrap();
    let json = dir.path().join("r.json");
    let out = run(&[
        "eval",
        s(&preds),
        s(&gt),
        "--protocol",
        "native",
        "--split",
        "all",
        "--bootstrap",
        "0",
        "--json",
        s(&json),
    ]);
    assert_eq!(out.status.code(), Some(0), "{}", text(&out));
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(stdout.contains("by color"), "{stdout}");
    let r: Value = serde_json::from_slice(&std::fs::read(&json).unwrap()).unwrap();
    assert_eq!(r["breakdowns"]["color"]["red"]["count"], 1, "{r}");
    assert_eq!(r["breakdowns"]["color"]["red"]["mIoU"], 1.0, "{r}");
}

/// Hostile pass (issue 21, repro-21): a ground-truth sample whose image is missing, a FIFO or
/// a link out of the dataset is an error naming it; it was left out silently ("9 images",
/// exit 0), which also shifts the splits (taken by position).
#[test]
fn eval_names_a_ground_truth_sample_without_its_image() {
    let preds = data("eval/preds/png");
    for how in ["missing", "fifo", "link out"] {
        let dir = tempfile::tempdir().unwrap();
        let g = dir.path().join("gt");
        copy_dir(&gt(), &g);
        let image = g.join("clevrtex_vbg/0/CLEVRTEX_vbg_000009.png");
        std::fs::remove_file(&image).unwrap();
        match how {
            "fifo" => {
                let st = std::process::Command::new("mkfifo")
                    .arg(&image)
                    .status()
                    .unwrap();
                assert!(st.success());
            }
            "link out" => std::os::unix::fs::symlink(
                gt().join("clevrtex_vbg/0/CLEVRTEX_vbg_000009.png"),
                &image,
            )
            .unwrap(),
            _ => {}
        }
        let args: Vec<&std::ffi::OsStr> = ["eval".as_ref(), preds.as_os_str(), g.as_os_str()]
            .into_iter()
            .chain(["--split", "all", "--bootstrap", "0"].map(std::ffi::OsStr::new))
            .collect();
        let out = crate::util::run_within(&args, 60);
        let t = text(&out);
        assert_eq!(out.status.code(), Some(1), "{how}: {t}");
        assert!(t.contains("CLEVRTEX_vbg_000009.png"), "{how}: {t}");
        // Issue 42: a FIFO was called "skipped" by a run that stopped (exit 1) over it.
        assert!(!t.contains("skipped"), "{how}: {t}");
    }
}

/// Third hostile pass (issue 21): object names from the ground truth's metadata reach the
/// table escaped (an OSC title sequence and a screen clear were printed raw).
#[test]
fn eval_prints_metadata_names_escaped() {
    let dir = tempfile::tempdir().unwrap();
    let g = dir.path().join("gt");
    copy_dir(&gt(), &g);
    let f = g.join("clevrtex_vbg/0/CLEVRTEX_vbg_000000.json");
    let mut m: Value = serde_json::from_slice(&std::fs::read(&f).unwrap()).unwrap();
    for o in m["objects"].as_array_mut().unwrap() {
        o["shape"] = "\u{1b}]0;PWNED\u{7}\u{1b}[2J".into();
    }
    std::fs::write(&f, m.to_string()).unwrap();
    let preds = data("eval/preds/png");
    let out = run(&[
        "eval",
        s(&preds),
        s(&g),
        "--split",
        "all",
        "--bootstrap",
        "0",
    ]);
    assert_eq!(out.status.code(), Some(0), "{}", text(&out));
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(
        stdout.contains("PWNED") && !stdout.contains('\u{1b}'),
        "{stdout}"
    );
}

/// Issue 34: `eval` scored ground truth whose mask holds ids past its metadata's objects
/// (which `verify` rejects), and treated predictions nested deeper than its walk's limit as
/// missing without saying why.
#[test]
fn eval_refuses_ids_past_the_objects_and_names_predictions_too_deep() {
    let dir = tempfile::tempdir().unwrap();
    let g = dir.path().join("gt");
    copy_dir(&gt(), &g);
    let meta_path = g.join("clevrtex_vbg/0/CLEVRTEX_vbg_000002.json");
    let mut meta: Value = serde_json::from_slice(&std::fs::read(&meta_path).unwrap()).unwrap();
    meta["objects"] = serde_json::json!([]);
    meta["num_objects"] = 0.into();
    std::fs::write(&meta_path, meta.to_string()).unwrap();
    let out = run(&["eval", s(&data("eval/preds/png")), s(&g), "--split", "all"]);
    assert_eq!(out.status.code(), Some(1), "{}", text(&out));
    let e = stderr(&out);
    assert!(
        e.contains("CLEVRTEX_vbg_000002_flat.png")
            && e.contains("has id 1 but its metadata")
            && e.contains("has 0 objects"),
        "{}",
        text(&out)
    );
    // A prediction 40 folders down is named as too deep, not just missing.
    let preds = dir.path().join("preds");
    copy_dir(&data("eval/preds/png"), &preds);
    let mut deep = preds.clone();
    for i in 0..40 {
        deep = deep.join(format!("d{i}"));
    }
    std::fs::create_dir_all(&deep).unwrap();
    let name = "CLEVRTEX_vbg_000000_mask.png";
    std::fs::rename(preds.join(name), deep.join(name)).unwrap();
    let out = run(&["eval", s(&preds), s(&gt()), "--split", "all"]);
    assert_ne!(out.status.code(), Some(0), "{}", text(&out));
    assert!(
        text(&out).contains("lies more than 32 folders deep; not read"),
        "{}",
        text(&out)
    );
}

/// Issue 34: `eval --json/--csv` wrote `<FILE>.tmp` (a generic name) through whatever was
/// there and removed it on a write error, deleting a user's own file of that name, and wrote
/// through a link planted there. With the one atomic writer, a user's `<FILE>.tmp` and a link
/// there are left as they are, on success and on error.
#[test]
fn eval_leaves_a_users_file_and_a_link_at_the_old_temporary_names() {
    let dir = tempfile::tempdir().unwrap();
    let outside = dir.path().join("victim");
    std::fs::write(&outside, b"theirs").unwrap();
    let json = dir.path().join("r.json");
    let csv = dir.path().join("r.csv");
    let user = dir.path().join("r.json.tmp");
    std::fs::write(&user, b"user data").unwrap();
    std::os::unix::fs::symlink(&outside, dir.path().join("r.csv.tmp")).unwrap();
    let preds = data("eval/preds/png");
    let eval = |json: &Path| {
        run(&[
            "eval",
            s(&preds),
            s(&gt()),
            "--split",
            "all",
            "--json",
            s(json),
            "--csv",
            s(&csv),
        ])
    };
    let out = eval(&json);
    assert_eq!(out.status.code(), Some(0), "{}", text(&out));
    assert!(json.symlink_metadata().unwrap().is_file());
    assert!(csv.symlink_metadata().unwrap().is_file());
    // FILE is a folder: the write fails (exit 1), the user's file of the old name stays.
    let folder = dir.path().join("d.json");
    std::fs::create_dir(&folder).unwrap();
    let user2 = dir.path().join("d.json.tmp");
    std::fs::write(&user2, b"user data").unwrap();
    let out = eval(&folder);
    assert_eq!(out.status.code(), Some(1), "{}", text(&out));
    assert_eq!(std::fs::read(&user).unwrap(), b"user data");
    assert_eq!(std::fs::read(&user2).unwrap(), b"user data");
    assert_eq!(std::fs::read(&outside).unwrap(), b"theirs");
    let left: Vec<String> = std::fs::read_dir(dir.path())
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .filter(|n| n.ends_with(".clevrtex-tmp"))
        .collect();
    assert!(left.is_empty(), "temporaries left: {left:?}");
}
