//! `clevrtex report`: an HTML page of a real generated dataset, of a hand-made one in the
//! published ClevrTex layout, the two compared, bad input, and the page loaded by a real
//! headless Chromium (no broken images, no console messages, a non-blank screenshot).

use std::path::{Path, PathBuf};
use std::process::Command;

use serde_json::Value;

use crate::util::{blender_or_skip, chromium_or_skip, clevrtex, published_copy, text};

/// Generate `n` images of each of `variants` (64x48, 1 sample, rgb, mask and depth).
fn generate(blender: &Path, out: &Path, variants: &[&str], n: u32) {
    for v in variants {
        let o = clevrtex()
            .args([
                "generate",
                "--variant",
                v,
                "-n",
                &n.to_string(),
                "--seed",
                "5",
            ])
            .args(["--width", "64", "--height", "48", "--samples", "1"])
            .args(["--passes", "rgb,mask,depth", "--blender"])
            .arg(blender)
            .arg("--out")
            .arg(out)
            .output()
            .unwrap();
        assert_eq!(o.status.code(), Some(0), "{}", text(&o));
    }
}

fn report(args: &[&Path], extra: &[&str], out: &Path) -> (Option<i32>, String) {
    let mut c = clevrtex();
    c.arg("report").args(extra).arg("--out").arg(out);
    for a in args {
        c.arg(a);
    }
    let o = c.output().unwrap();
    (o.status.code(), text(&o))
}

/// The median ΔE of `variant` in the contrast table of a one-dataset report.
fn median_delta_e(html: &str, variant: &str) -> f64 {
    let cells = html
        .split("<tr>")
        .map(|row| {
            row.split("<td>")
                .skip(1)
                .map(|c| c.split('<').next().unwrap())
                .collect::<Vec<&str>>()
        })
        .find(|c| c.len() >= 5 && c[1] == variant && c[2].contains(" of "))
        .unwrap_or_else(|| panic!("no contrast row for {variant}"));
    // dataset, variant, images measured, objects, ΔE median, ...
    cells[4].parse().unwrap()
}

/// Every `<img>`'s `src` (the report must embed them all).
fn img_sources(html: &str) -> Vec<&str> {
    html.split("<img ")
        .skip(1)
        .map(|t| t.split("src=\"").nth(1).unwrap().split('"').next().unwrap())
        .collect()
}

#[test]
fn report_of_a_generated_and_a_published_layout_dataset_and_both_compared() {
    let Some(blender) = blender_or_skip("report_of_a_generated_dataset") else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let data = dir.path().join("data");
    generate(&blender, &data, &["clevr", "camo"], 5);
    // The run manifest records the seconds spent on each sample (the report plots them).
    let manifest: Value = serde_json::from_slice(
        &std::fs::read(data.join("clevrtex_clevr/MANIFEST-0-5-0of1.json")).unwrap(),
    )
    .unwrap();
    let secs = manifest["sample_seconds"].as_object().unwrap();
    assert_eq!(secs.len(), 5, "{secs:?}");
    assert!(secs.values().all(|s| s.as_f64().unwrap() > 0.0), "{secs:?}");
    // A rerun that skips the finished samples keeps their times.
    generate(&blender, &data, &["clevr"], 5);
    let again: Value = serde_json::from_slice(
        &std::fs::read(data.join("clevrtex_clevr/MANIFEST-0-5-0of1.json")).unwrap(),
    )
    .unwrap();
    assert_eq!(again["sample_seconds"], manifest["sample_seconds"]);
    let page = dir.path().join("report.html");
    let (code, t) = report(&[&data], &["--preview", "3"], &page);
    assert_eq!(code, Some(0), "{t}");
    assert!(t.contains("10 image(s) read, 10 measured"), "{t}");
    let html = std::fs::read_to_string(&page).unwrap();
    // Self-contained: no script, nothing fetched, every image a data URI.
    assert!(!html.contains("<script"));
    assert!(!html.contains("http://") && !html.contains("https://"));
    let srcs = img_sources(&html);
    assert!(srcs.len() >= 15, "{}", srcs.len());
    assert!(
        srcs.iter().all(|s| s.starts_with("data:image/")),
        "{srcs:?}"
    );
    assert_eq!(
        srcs.iter()
            .filter(|s| s.starts_with("data:image/png"))
            .count(),
        1
    );
    for section in [
        "Images per variant and split",
        "Failure ledger",
        "Objects per image",
        "vs uniform 3..10",
        "Visible pixels per object",
        "more than 8 px at this resolution",
        "Share of each object occluded",
        "Camera jitter",
        "Time per image (s)",
        "Rejected layouts per image",
        "Nearest depth per image (m)",
        "Provenance",
        "seed",
    ] {
        assert!(html.contains(section), "missing `{section}`");
    }
    // Two variants in one folder: the scene statistics get one part per variant, not one
    // pooled histogram (camo's objects beside clevr's).
    for v in ["clevr", "camo"] {
        for heading in ["Scenes", "Visibility", "Camera, lights and rendering"] {
            assert_eq!(
                html.matches(&format!("<h2>{v}: {heading}</h2>")).count(),
                1,
                "no `{v}: {heading}` part"
            );
        }
    }
    assert!(!html.contains("<h2>Scenes</h2>"), "a pooled scenes section");
    // The lights of every image are recomputed from its seed (the built-in configs), counted
    // per variant.
    assert_eq!(
        html.matches("5 of 5 images recomputed").count(),
        2,
        "lights not recomputed per variant"
    );
    // Camo objects are made to blend in: far less colour contrast than clevr's plain colours.
    let (clevr, camo) = (
        median_delta_e(&html, "clevr"),
        median_delta_e(&html, "camo"),
    );
    assert!(camo < clevr, "camo ΔE {camo} >= clevr ΔE {clevr}");
    // Our metadata has everything: nothing is "not in this dataset" but the colours of camo,
    // whose objects have none (the one figure in camo's part of the page that says so).
    let camo_part = html
        .split("<h2>camo: Scenes</h2>")
        .nth(1)
        .and_then(|t| t.split("<h2>clevr: Scenes</h2>").next())
        .unwrap();
    assert_eq!(
        html.matches("not in this dataset").count(),
        1,
        "something missing"
    );
    assert_eq!(camo_part.matches("not in this dataset").count(), 1);

    // The published layout: no manifest, no visibility, no camera.
    let published = dir.path().join("clevrtex");
    published_copy(&data, "clevr", &published);
    let page2 = dir.path().join("published.html");
    let (code, t) = report(&[&published], &["--preview", "2"], &page2);
    assert_eq!(code, Some(0), "{t}");
    let html2 = std::fs::read_to_string(&page2).unwrap();
    assert!(html2.contains("run manifest: not in this dataset"));
    assert!(html2.contains("Visible pixels per object</h3><p class=\"na\">not in this dataset"));
    assert!(html2.contains("Light jitter</h3><p class=\"na\">not in this dataset"));
    // Its pixels are there: the contrast and depth need only the passes.
    assert!(html2.contains("Objects per image"));

    // Compared: every statistic with a two-sample test; the same images give high p-values.
    let page3 = dir.path().join("compare.html");
    let (code, t) = report(
        &[&data.join("clevrtex_clevr")],
        &["--compare", published.to_str().unwrap(), "--preview", "1"],
        &page3,
    );
    assert_eq!(code, Some(0), "{t}");
    let html3 = std::fs::read_to_string(&page3).unwrap();
    assert!(html3.contains("A clevrtex_clevr") && html3.contains("B clevrtex"));
    assert!(
        html3.contains("two-sample chi-square: χ² = 0.00"),
        "shapes of equal data differ"
    );
    assert!(html3.contains("two-sample Kolmogorov-Smirnov on x: D = 0.0000"));
    assert!(html3.contains("B clevrtex: not in this dataset"));
}

#[test]
fn report_names_a_missing_or_broken_dataset_and_keeps_the_old_page() {
    let dir = tempfile::tempdir().unwrap();
    let page = dir.path().join("r.html");
    let (code, t) = report(&[&dir.path().join("nope")], &[], &page);
    assert_eq!(code, Some(1), "{t}");
    assert!(
        t.contains("dataset folder") && t.contains("does not exist") && t.contains("hint:"),
        "{t}"
    );
    assert!(!page.exists());

    // A broken metadata file: the error names it, the page written before is kept.
    let sub = dir.path().join("ds/clevrtex_clevr/0");
    std::fs::create_dir_all(&sub).unwrap();
    std::fs::write(sub.join("CLEVRTEX_clevr_000000.json"), "{\"objects\": [").unwrap();
    std::fs::write(&page, "old").unwrap();
    let (code, t) = report(&[&dir.path().join("ds")], &[], &page);
    assert_eq!(code, Some(1), "{t}");
    assert!(
        t.contains("CLEVRTEX_clevr_000000.json` is not valid metadata"),
        "{t}"
    );
    assert_eq!(std::fs::read_to_string(&page).unwrap(), "old");

    let empty = dir.path().join("empty");
    std::fs::create_dir_all(&empty).unwrap();
    let (code, t) = report(&[&empty], &[], &page);
    assert_eq!(code, Some(1), "{t}");
    assert!(t.contains("no `clevrtex_<variant>` folder"), "{t}");
}

/// Run headless Chromium with the flags that work as root in a container.
fn chromium(bin: &Path, profile: &Path, extra: &[String], url: &str) -> std::process::Output {
    Command::new(bin)
        .args([
            "--headless",
            "--no-sandbox",
            "--disable-gpu",
            "--disable-quic",
            "--no-first-run",
            "--disable-background-networking",
            "--disable-component-update",
            "--disable-sync",
            "--hide-scrollbars",
        ])
        .arg(format!("--user-data-dir={}", profile.display()))
        .args(extra)
        .arg(url)
        .output()
        .unwrap()
}

#[test]
fn report_loads_in_headless_chromium_without_broken_images_or_console_messages() {
    let Some(blender) = blender_or_skip("report_loads_in_headless_chromium") else {
        return;
    };
    let Some(browser) = chromium_or_skip("report_loads_in_headless_chromium") else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let data = dir.path().join("data");
    generate(&blender, &data, &["full"], 3);
    let page = dir.path().join("report.html");
    let (code, t) = report(&[&data], &[], &page);
    assert_eq!(code, Some(0), "{t}");
    let html = std::fs::read_to_string(&page).unwrap();
    let images = html.matches("<img ").count();
    let url = |p: &Path| format!("file://{}", p.display());
    let profile = |n: &str| -> PathBuf {
        let p = dir.path().join(n);
        std::fs::create_dir_all(&p).unwrap();
        p
    };

    // 1. The page itself, with Chromium's log on stderr: the page has no script, so any
    //    console line (an error loading something, a CSP or parse complaint) is a failure.
    let o = chromium(
        &browser,
        &profile("p1"),
        &[
            "--enable-logging=stderr".into(),
            "--v=0".into(),
            "--virtual-time-budget=5000".into(),
            "--dump-dom".into(),
        ],
        &url(&page),
    );
    let stderr = String::from_utf8_lossy(&o.stderr);
    assert!(o.status.success(), "chromium failed:\n{stderr}");
    let console: Vec<&str> = stderr.lines().filter(|l| l.contains(":CONSOLE")).collect();
    assert!(console.is_empty(), "console messages: {console:#?}");
    assert!(String::from_utf8_lossy(&o.stdout).contains("Dataset report"));

    // 2. A copy with a check appended: after load, every <img> decoded (naturalWidth > 0).
    let check = r#"<script>window.addEventListener("load",()=>{const i=[...document.images];const d=document.createElement("pre");d.id="clevrtex-check";d.textContent=JSON.stringify({images:i.length,broken:i.filter(x=>!(x.complete&&x.naturalWidth>0)).map(x=>x.alt)});document.body.appendChild(d);});</script></body>"#;
    let checked = dir.path().join("checked.html");
    std::fs::write(&checked, html.replace("</body>", check)).unwrap();
    let o = chromium(
        &browser,
        &profile("p2"),
        &[
            "--virtual-time-budget=5000".into(),
            "--run-all-compositor-stages-before-draw".into(),
            "--dump-dom".into(),
        ],
        &url(&checked),
    );
    let dom = String::from_utf8_lossy(&o.stdout);
    let json = dom
        .split("<pre id=\"clevrtex-check\">")
        .nth(1)
        .and_then(|t| t.split("</pre>").next())
        .unwrap_or_else(|| {
            panic!(
                "the check did not run:\n{}",
                String::from_utf8_lossy(&o.stderr)
            )
        });
    let v: Value = serde_json::from_str(&json.replace("&amp;", "&")).unwrap();
    assert_eq!(v["images"].as_u64(), Some(images as u64), "{v}");
    assert_eq!(v["broken"], serde_json::json!([]), "broken images: {v}");

    // 3. A screenshot of the right size that is not blank.
    let shot = dir.path().join("shot.png");
    let o = chromium(
        &browser,
        &profile("p3"),
        &[
            "--window-size=1200,2400".into(),
            "--virtual-time-budget=5000".into(),
            format!("--screenshot={}", shot.display()),
        ],
        &url(&page),
    );
    assert!(
        shot.is_file(),
        "no screenshot:\n{}",
        String::from_utf8_lossy(&o.stderr)
    );
    let img = image::open(&shot).unwrap().to_luma8();
    assert_eq!(img.dimensions(), (1200, 2400));
    let n = img.len() as f64;
    let mean = img.iter().map(|&p| f64::from(p)).sum::<f64>() / n;
    let var = img
        .iter()
        .map(|&p| (f64::from(p) - mean).powi(2))
        .sum::<f64>()
        / n;
    // A blank page has variance 0; text, plots and the sheet give hundreds.
    assert!(
        var > 100.0,
        "screenshot looks blank: mean {mean:.1}, variance {var:.1}"
    );
    let dark = img.iter().filter(|&&p| p < 128).count() as f64 / n;
    assert!(dark > 0.01, "almost nothing drawn: {dark}");
}

/// Samples the report cannot use (RGB and mask of different sizes, metadata that is not
/// valid, a link out of the dataset, a FIFO) are named and left out; the page is written
/// (exit 3). Before, the size mismatch panicked (exit 101), one bad metadata file failed the
/// whole report and a FIFO hung it.
#[test]
fn report_leaves_out_samples_it_cannot_use_and_names_them() {
    let dir = tempfile::tempdir().unwrap();
    let data = dir.path().join("data");
    for i in 0..5 {
        let mask = if i == 1 { (8, 6) } else { (16, 12) };
        crate::util::hand_png_sample(&data, "clevr", i, (16, 12), mask);
    }
    let sub = data.join("clevrtex_clevr/0");
    std::fs::write(sub.join("CLEVRTEX_clevr_000002.json"), b"{\"objects\": 7}").unwrap();
    let outside = dir.path().join("elsewhere.json");
    std::fs::copy(sub.join("CLEVRTEX_clevr_000000.json"), &outside).unwrap();
    std::fs::remove_file(sub.join("CLEVRTEX_clevr_000003.json")).unwrap();
    std::os::unix::fs::symlink(&outside, sub.join("CLEVRTEX_clevr_000003.json")).unwrap();
    std::fs::remove_file(sub.join("CLEVRTEX_clevr_000004.json")).unwrap();
    let st = std::process::Command::new("mkfifo")
        .arg(sub.join("CLEVRTEX_clevr_000004.json"))
        .status()
        .unwrap();
    assert!(st.success());
    let page = dir.path().join("report.html");
    let o = crate::util::run_within(
        &[
            "report".as_ref(),
            "--out".as_ref(),
            page.as_os_str(),
            data.as_os_str(),
        ],
        120,
    );
    let t = text(&o);
    assert_eq!(o.status.code(), Some(3), "{t}");
    assert!(
        t.contains("CLEVRTEX_clevr_000001") && t.contains("is 16x12 but its mask"),
        "{t}"
    );
    assert!(
        t.contains("CLEVRTEX_clevr_000002.json` is not valid metadata"),
        "{t}"
    );
    assert!(
        t.contains("CLEVRTEX_clevr_000003.json` is a symbolic link leading out"),
        "{t}"
    );
    assert!(
        t.contains("CLEVRTEX_clevr_000004.json` is not a regular file"),
        "{t}"
    );
    assert!(page.is_file(), "{t}");
}

/// The report measures a sample's pixels through the dataset reader too: an RGB image that is
/// a link out of the dataset is not read and the sample is named and left out of the
/// measurements (exit 3). Before, only the preview sheet left it out; the contrast
/// measurement read the file the link led to.
#[test]
fn report_measures_no_pass_file_behind_a_link_out_of_the_dataset() {
    let dir = tempfile::tempdir().unwrap();
    let data = dir.path().join("data");
    for i in 0..3 {
        crate::util::hand_png_sample(&data, "clevr", i, (16, 12), (16, 12));
    }
    let rgb = data.join("clevrtex_clevr/0/CLEVRTEX_clevr_000002.png");
    let outside = dir.path().join("secret.png");
    std::fs::rename(&rgb, &outside).unwrap();
    std::os::unix::fs::symlink(&outside, &rgb).unwrap();
    let page = dir.path().join("report.html");
    let o = crate::util::run_within(
        &[
            "report".as_ref(),
            "--preview".as_ref(),
            "0".as_ref(),
            "--out".as_ref(),
            page.as_os_str(),
            data.as_os_str(),
        ],
        120,
    );
    let t = text(&o);
    assert_eq!(o.status.code(), Some(3), "{t}");
    assert!(t.contains("3 image(s) read, 2 measured"), "{t}");
    assert!(
        t.contains("CLEVRTEX_clevr_000002.png` is a symbolic link leading out"),
        "{t}"
    );
    assert!(page.is_file(), "{t}");
}

/// Issue 34: a `_flat.png` of another PNG mode (RGB, 16-bit) made `report` panic ("capacity
/// overflow", exit 101), and `preview` drew an all-black RGB mask as if it were ids. Every
/// reader now names such a sample and leaves it out (exit 3), by one rule
/// (`dataset::png_mode_problem`).
#[test]
fn report_and_preview_leave_out_masks_of_another_png_mode() {
    let dir = tempfile::tempdir().unwrap();
    let data = dir.path().join("data");
    for i in 0..4 {
        crate::util::hand_png_sample(&data, "clevr", i, (16, 12), (16, 12));
    }
    let sub = data.join("clevrtex_clevr/0");
    image::RgbImage::new(16, 12)
        .save(sub.join("CLEVRTEX_clevr_000001_flat.png"))
        .unwrap();
    image::ImageBuffer::<image::Luma<u16>, Vec<u16>>::from_pixel(16, 12, image::Luma([300]))
        .save(sub.join("CLEVRTEX_clevr_000002_flat.png"))
        .unwrap();
    let page = dir.path().join("report.html");
    let sheet = dir.path().join("sheet.png");
    for (cmd, out) in [("report", &page), ("preview", &sheet)] {
        let o = crate::util::run_within(
            &[
                cmd.as_ref(),
                "--out".as_ref(),
                out.as_os_str(),
                data.as_os_str(),
            ],
            120,
        );
        let t = text(&o);
        assert_eq!(o.status.code(), Some(3), "{cmd}: {t}");
        assert!(
            t.contains("CLEVRTEX_clevr_000001_flat.png` is a 8-bit RGB PNG, but a mask pass must be 8-bit palette or greyscale object ids"),
            "{cmd}: {t}"
        );
        assert!(
            t.contains("CLEVRTEX_clevr_000002_flat.png` is a 16-bit greyscale PNG"),
            "{cmd}: {t}"
        );
        assert!(out.is_file(), "{cmd}: {t}");
    }
}
