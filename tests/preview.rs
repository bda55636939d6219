//! `clevrtex preview`: a contact sheet of a real generated dataset, and of a hand-made one in
//! the published ClevrTex layout (metadata with only the published keys).

use crate::util::{blender_or_skip, clevrtex, published_copy, text};

#[test]
fn preview_draws_one_row_per_sample_and_one_column_per_pass() {
    let Some(blender) = blender_or_skip("preview_draws_one_row_per_sample") else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let data = dir.path().join("data");
    let o = clevrtex()
        .args(["generate", "--variant", "clevr", "-n", "3", "--seed", "1"])
        .args(["--width", "64", "--height", "48", "--samples", "1"])
        .args(["--passes", "rgb,mask,depth", "--blender"])
        .arg(&blender)
        .arg("--out")
        .arg(&data)
        .output()
        .unwrap();
    assert_eq!(o.status.code(), Some(0), "{}", text(&o));
    let sheet = dir.path().join("sheet.png");
    let o = clevrtex()
        .args(["preview", "--cell", "64", "--out"])
        .arg(&sheet)
        .arg(&data)
        .output()
        .unwrap();
    let t = text(&o);
    assert_eq!(o.status.code(), Some(0), "{t}");
    assert!(
        t.contains("3 sample(s) x 4 column(s) (rgb, mask (ids), outlines, depth (m))"),
        "{t}"
    );
    let img = image::open(&sheet).unwrap().to_rgb8();
    // 4 columns of 64 px plus 10 px gaps; a header and 3 rows of label + 48 px + 6 px.
    assert_eq!(img.dimensions(), (4 * 74 + 10, 20 + 3 * (18 + 48 + 6)));
    // Each mask cell shows the objects in colour on black: many distinct colours.
    let mask_cell: std::collections::BTreeSet<[u8; 3]> = (0..48)
        .flat_map(|y| (0..64).map(move |x| (x, y)))
        .map(|(x, y)| img.get_pixel(74 + 10 + x, 20 + 18 + y).0)
        .collect();
    assert!(mask_cell.len() >= 3, "{mask_cell:?}");

    // The published ClevrTex layout: the same files with only the published metadata keys.
    let published = dir.path().join("clevrtex");
    published_copy(&data, "clevr", &published);
    let o = clevrtex()
        .args(["preview", "--indices", "2,0", "--out"])
        .arg(dir.path().join("published.png"))
        .arg(&published)
        .output()
        .unwrap();
    assert_eq!(o.status.code(), Some(0), "{}", text(&o));
    assert!(text(&o).contains("2 sample(s)"), "{}", text(&o));

    let o = clevrtex()
        .args(["preview", "--indices", "7", "--out"])
        .arg(dir.path().join("none.png"))
        .arg(&data)
        .output()
        .unwrap();
    assert_eq!(o.status.code(), Some(1), "{}", text(&o));
    assert!(text(&o).contains("no sample with index 7"), "{}", text(&o));
    assert!(!dir.path().join("none.png").exists());
}

/// A sample whose RGB image and mask differ in size is reported and left empty; the sheet is
/// still written (exit 3). Before, drawing its outlines panicked (exit 101).
#[test]
fn preview_reports_a_sample_whose_rgb_and_mask_differ_in_size_and_goes_on() {
    let dir = tempfile::tempdir().unwrap();
    let data = dir.path().join("data");
    crate::util::hand_png_sample(&data, "clevr", 0, (16, 12), (16, 12));
    crate::util::hand_png_sample(&data, "clevr", 1, (16, 12), (8, 6));
    let sheet = dir.path().join("sheet.png");
    let o = clevrtex()
        .args(["preview", "--cell", "32", "--out"])
        .arg(&sheet)
        .arg(&data)
        .output()
        .unwrap();
    let t = text(&o);
    assert_eq!(o.status.code(), Some(3), "{t}");
    assert!(
        t.contains("CLEVRTEX_clevr_000001") && t.contains("is 16x12 but its mask"),
        "{t}"
    );
    assert!(
        !t.contains("CLEVRTEX_clevr_000000:"),
        "the good sample is not reported: {t}"
    );
    assert!(sheet.is_file(), "{t}");
}

/// A sample of another shape (RGB and mask 1x4096, the largest side, a few hundred bytes each)
/// is shrunk into its cell, and a first sample of that shape does not make every row 4096
/// cells tall: it was scaled to the cell's width (1024x4194304) and the sheet sized by it,
/// gigabytes for a tiny file (an abort under a memory limit).
#[test]
fn preview_shrinks_a_tall_thin_sample_into_its_cell() {
    let dir = tempfile::tempdir().unwrap();
    let data = dir.path().join("data");
    crate::util::hand_png_sample(&data, "clevr", 0, (16, 12), (16, 12));
    crate::util::hand_png_sample(&data, "clevr", 1, (1, 4096), (1, 4096));
    for (indices, rows) in [("0,1", 768), ("1,0", 2048)] {
        let sheet = dir.path().join(format!("sheet-{indices}.png"));
        let args: Vec<&std::ffi::OsStr> = vec![
            "preview".as_ref(),
            "--cell".as_ref(),
            "1024".as_ref(),
            "--indices".as_ref(),
            indices.as_ref(),
            "--out".as_ref(),
            sheet.as_os_str(),
            data.as_os_str(),
        ];
        let (code, t) = crate::util::run_limited(&args, &[], 120);
        assert_eq!(code, Some(0), "--indices {indices}: {t}");
        // 3 columns (rgb, mask, outlines) of 1024 px; rows 768 px (4:3) or, with the tall
        // sample first, at most twice the cell's width.
        let (w, h) = image::image_dimensions(&sheet).unwrap();
        assert_eq!((w, h), (3 * 1034 + 10, 20 + 2 * (18 + rows + 6)), "{t}");
    }
}

/// A link out of the dataset is not followed and a FIFO is not opened (it hung the command);
/// both are reported, the sheet is written.
#[test]
fn preview_follows_no_link_out_of_the_dataset_and_opens_no_fifo() {
    let dir = tempfile::tempdir().unwrap();
    let data = dir.path().join("data");
    for i in 0..3 {
        crate::util::hand_png_sample(&data, "clevr", i, (16, 12), (16, 12));
    }
    let sub = data.join("clevrtex_clevr/0");
    let outside = dir.path().join("secret.png");
    image::RgbImage::from_pixel(16, 12, image::Rgb([255, 0, 0]))
        .save(&outside)
        .unwrap();
    std::fs::remove_file(sub.join("CLEVRTEX_clevr_000001.png")).unwrap();
    std::os::unix::fs::symlink(&outside, sub.join("CLEVRTEX_clevr_000001.png")).unwrap();
    std::fs::remove_file(sub.join("CLEVRTEX_clevr_000002_flat.png")).unwrap();
    let st = std::process::Command::new("mkfifo")
        .arg(sub.join("CLEVRTEX_clevr_000002_flat.png"))
        .status()
        .unwrap();
    assert!(st.success());
    let sheet = dir.path().join("sheet.png");
    let o = crate::util::run_within(
        &[
            "preview".as_ref(),
            "--cell".as_ref(),
            "32".as_ref(),
            "--out".as_ref(),
            sheet.as_os_str(),
            data.as_os_str(),
        ],
        60,
    );
    let t = text(&o);
    assert_eq!(o.status.code(), Some(3), "{t}");
    assert!(
        t.contains("CLEVRTEX_clevr_000001.png` is a symbolic link leading out of the dataset"),
        "{t}"
    );
    assert!(
        t.contains("CLEVRTEX_clevr_000002_flat.png` is not a regular file"),
        "{t}"
    );
    // Nothing of the outside file on the sheet: no pure red pixel.
    let img = image::open(&sheet).unwrap().to_rgb8();
    assert!(
        !img.pixels().any(|p| p.0 == [255, 0, 0]),
        "the linked file was drawn"
    );
}

/// `--out` inside the dataset is refused before anything is written (it could overwrite a
/// sample's file).
#[test]
fn preview_and_report_refuse_an_output_inside_the_dataset() {
    let dir = tempfile::tempdir().unwrap();
    let data = dir.path().join("data");
    crate::util::hand_png_sample(&data, "clevr", 0, (16, 12), (16, 12));
    let victim = data.join("clevrtex_clevr/0/CLEVRTEX_clevr_000000.png");
    let before = std::fs::read(&victim).unwrap();
    for (cmd, out) in [
        ("preview", victim.clone()),
        (
            "report",
            data.join("clevrtex_clevr/0/CLEVRTEX_clevr_000000.html"),
        ),
        ("report", victim.clone()),
    ] {
        let o = clevrtex()
            .arg(cmd)
            .arg("--out")
            .arg(&out)
            .arg(&data)
            .output()
            .unwrap();
        let t = text(&o);
        assert_eq!(o.status.code(), Some(1), "{cmd}: {t}");
        assert!(t.contains("is inside the dataset"), "{cmd}: {t}");
        assert_eq!(
            std::fs::read(&victim).unwrap(),
            before,
            "{cmd} overwrote a sample's file"
        );
        if out != victim {
            assert!(!out.exists(), "{cmd} wrote into the dataset");
        }
    }
}

/// A mask PNG whose header declares 200000x200000 pixels (a few hundred bytes on disk) is
/// reported from its header, never decoded: it cost a 40 GB allocation (an abort under a
/// memory limit); the other sample is drawn.
#[test]
fn preview_checks_a_mask_png_size_from_its_header_before_decoding() {
    let dir = tempfile::tempdir().unwrap();
    let data = dir.path().join("data");
    crate::util::hand_png_sample(&data, "clevr", 0, (16, 12), (16, 12));
    crate::util::hand_png_sample(&data, "clevr", 1, (16, 12), (16, 12));
    let mask = data.join("clevrtex_clevr/0/CLEVRTEX_clevr_000001_flat.png");
    let mut bytes = std::fs::read(&mask).unwrap();
    assert_eq!(&bytes[12..16], b"IHDR");
    bytes[16..20].copy_from_slice(&200_000u32.to_be_bytes());
    bytes[20..24].copy_from_slice(&200_000u32.to_be_bytes());
    let crc = crc32fast::hash(&bytes[12..29]);
    bytes[29..33].copy_from_slice(&crc.to_be_bytes());
    std::fs::write(&mask, bytes).unwrap();
    let sheet = dir.path().join("sheet.png");
    let args: Vec<&std::ffi::OsStr> = vec![
        "preview".as_ref(),
        "--cell".as_ref(),
        "32".as_ref(),
        "--out".as_ref(),
        sheet.as_os_str(),
        data.as_os_str(),
    ];
    let (code, t) = crate::util::run_limited(&args, &[], 120);
    assert_eq!(code, Some(3), "{t}");
    assert!(
        t.contains("CLEVRTEX_clevr_000001_flat.png") && t.contains("declares 200000x200000"),
        "{t}"
    );
    assert!(sheet.is_file(), "{t}");
}

/// Hostile pass (issue 21, repro-03, 04, 05, 09): a sample whose metadata is not an object,
/// does not parse, is a folder, or fails the shared check (`num_objects` -1), or whose image is
/// missing, is named and left out (exit 3), and the others are drawn; `preview` drew them
/// silently (exit 0) or failed the whole run (exit 1), `report` used invalid metadata.
#[test]
fn preview_and_report_leave_out_a_broken_sample_and_say_so() {
    let dir = tempfile::tempdir().unwrap();
    let data = dir.path().join("data");
    for i in 0..5 {
        crate::util::hand_png_sample(&data, "clevr", i, (16, 12), (16, 12));
    }
    let sub = data.join("clevrtex_clevr/0");
    let meta = |i: u64| sub.join(format!("CLEVRTEX_clevr_{i:06}.json"));
    // (what the message says, how the copy is damaged)
    type Case<'a> = (&'a str, Box<dyn Fn() + 'a>);
    let cases: [Case; 4] = [
        (
            "is [1,2,3], not an object",
            Box::new(|| std::fs::write(meta(1), "[1, 2, 3]").unwrap()),
        ),
        (
            "is not valid metadata",
            Box::new(|| std::fs::write(meta(1), "{{").unwrap()),
        ),
        (
            "`num_objects`",
            Box::new(|| {
                let m = r#"{"image_index": 1, "split": "test", "num_objects": -1, "objects": []}"#;
                std::fs::write(meta(1), m).unwrap()
            }),
        ),
        (
            "CLEVRTEX_clevr_000001.png` is missing",
            Box::new(|| std::fs::remove_file(sub.join("CLEVRTEX_clevr_000001.png")).unwrap()),
        ),
    ];
    for (i, (want, damage)) in cases.iter().enumerate() {
        let copy = dir.path().join(format!("case{i}"));
        let st = std::process::Command::new("cp")
            .arg("-a")
            .arg(&data)
            .arg(&copy)
            .status()
            .unwrap();
        assert!(st.success());
        std::fs::rename(&data, dir.path().join("orig")).unwrap();
        std::fs::rename(&copy, &data).unwrap();
        damage();
        let sheet = dir.path().join(format!("s{i}.png"));
        let o = clevrtex()
            .arg("preview")
            .arg(&data)
            .arg("--out")
            .arg(&sheet)
            .output()
            .unwrap();
        let t = text(&o);
        assert_eq!(o.status.code(), Some(3), "{want}: {t}");
        assert!(t.contains(want) && sheet.is_file(), "{want}: {t}");
        if i < 3 {
            let page = dir.path().join(format!("r{i}.html"));
            let o = clevrtex()
                .arg("report")
                .arg(&data)
                .arg("--out")
                .arg(&page)
                .output()
                .unwrap();
            let t = text(&o);
            assert_eq!(o.status.code(), Some(3), "report, {want}: {t}");
            assert!(page.is_file(), "report, {want}: {t}");
        }
        std::fs::remove_dir_all(&data).unwrap();
        std::fs::rename(dir.path().join("orig"), &data).unwrap();
    }
}

/// Issue 42, minor: `preview --out out/x.png` into a missing folder failed where every other
/// writer of an `--out` makes the folder.
#[test]
fn preview_makes_the_folder_of_its_out() {
    let dir = tempfile::tempdir().unwrap();
    let data = dir.path().join("data");
    crate::util::hand_png_sample(&data, "clevr", 0, (16, 12), (16, 12));
    let sheet = dir.path().join("new/deeper/x.png");
    let o = clevrtex()
        .args(["preview", "--out"])
        .arg(&sheet)
        .arg(&data)
        .output()
        .unwrap();
    assert_eq!(o.status.code(), Some(0), "{}", text(&o));
    assert!(image::image_dimensions(&sheet).is_ok(), "{}", text(&o));
}
