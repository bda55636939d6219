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
