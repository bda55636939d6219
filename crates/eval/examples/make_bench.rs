//! Write a synthetic benchmark for `clevrtex eval`: N ground-truth samples of 320x240 in the
//! published layout (RGB image, palette `_flat.png`, metadata) and 128x128 predictions
//! (`_mask.png` and `_recon.png`).
//!
//! ```text
//! cargo run --release -p clevrtex-eval --example make_bench -- /tmp/evalbench 10000
//! clevrtex eval /tmp/evalbench/preds /tmp/evalbench/gt --split all
//! ```

use std::io::BufWriter;
use std::path::Path;

use rand::{Rng, SeedableRng};
use rayon::prelude::*;

fn write_png(
    path: &Path,
    w: u32,
    h: u32,
    color: png::ColorType,
    palette: Option<&[u8]>,
    data: &[u8],
) {
    let f = std::fs::File::create(path).expect("create file");
    let mut enc = png::Encoder::new(BufWriter::new(f), w, h);
    enc.set_color(color);
    enc.set_depth(png::BitDepth::Eight);
    if let Some(p) = palette {
        enc.set_palette(p.to_vec());
    }
    let mut wr = enc.write_header().expect("png header");
    wr.write_image_data(data).expect("png data");
}

fn main() {
    let mut args = std::env::args().skip(1);
    let root = args.next().unwrap_or_else(|| "/tmp/evalbench".into());
    let n: usize = args.next().and_then(|s| s.parse().ok()).unwrap_or(10_000);
    let root = Path::new(&root);
    let palette: Vec<u8> = (0..256u32)
        .flat_map(|i| [(i * 40) as u8, (i * 90) as u8, (i * 150) as u8])
        .collect();
    let materials = ["bricks", "moss", "denim", "rope", "marble", "rust"];
    let shapes = ["cube", "sphere", "cylinder", "monkey"];
    let sizes = ["small", "medium", "large"];
    (0..n).into_par_iter().for_each(|idx| {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(idx as u64);
        let gt_dir = root.join(format!("gt/clevrtex_full/{}", idx / 1000));
        let pred_dir = root.join(format!("preds/{}", idx / 1000));
        std::fs::create_dir_all(&gt_dir).expect("mkdir");
        std::fs::create_dir_all(&pred_dir).expect("mkdir");
        let stem = format!("CLEVRTEX_full_{idx:06}");
        let (w, h) = (320usize, 240usize);
        let k = rng.random_range(3..=10usize);
        let mut mask = vec![0u8; w * h];
        let mut objects = Vec::new();
        for o in 0..k {
            let (cx, cy) = (
                rng.random_range(40.0..280.0f64),
                rng.random_range(40.0..200.0f64),
            );
            let r = rng.random_range(10.0..35.0f64);
            for y in 0..h {
                for x in 0..w {
                    let (dx, dy) = (x as f64 - cx, (y as f64 - cy) * 1.3);
                    if dx * dx + dy * dy < r * r {
                        mask[y * w + x] = o as u8 + 1;
                    }
                }
            }
            objects.push(serde_json::json!({
                "shape": shapes[rng.random_range(0..4)],
                "size": sizes[rng.random_range(0..3)],
                "material": materials[rng.random_range(0..6)],
                "color": "gray",
                "index": o,
            }));
        }
        // A textured-looking image: smooth shading per segment plus noise, so the PNG costs
        // about as much to decode as a render.
        let mut img = vec![0u8; w * h * 3];
        for y in 0..h {
            for x in 0..w {
                let l = mask[y * w + x] as usize;
                for c in 0..3 {
                    let base = (x * (c + 1) / 3 + y / 2 + l * 37 * (c + 2)) % 200;
                    img[(y * w + x) * 3 + c] =
                        (base as i32 + rng.random_range(-24..=24)).clamp(0, 255) as u8;
                }
            }
        }
        write_png(
            &gt_dir.join(format!("{stem}.png")),
            w as u32,
            h as u32,
            png::ColorType::Rgb,
            None,
            &img,
        );
        write_png(
            &gt_dir.join(format!("{stem}_flat.png")),
            w as u32,
            h as u32,
            png::ColorType::Indexed,
            Some(&palette),
            &mask,
        );
        let meta = serde_json::json!({
            "image_index": idx, "num_objects": k, "split": "test",
            "image_filename": format!("{stem}.png"), "ground_material": materials[idx % 6],
            "objects": objects,
        });
        std::fs::write(gt_dir.join(format!("{stem}.json")), meta.to_string()).expect("write json");

        // Predictions: the true mask (crop + nearest), with slots permuted and some blocks
        // wrong; the reconstruction is the true image crop with noise.
        let truth = clevrtex_eval::resize::crop_resize_nearest(
            &mask.iter().map(|&v| v as u32).collect::<Vec<_>>(),
            w,
            h,
            128,
        )
        .expect("crop");
        let slots = 11u8;
        let perm: Vec<u8> = {
            let mut p: Vec<u8> = (0..slots).collect();
            for i in (1..p.len()).rev() {
                p.swap(i, rng.random_range(0..=i));
            }
            p
        };
        let pred: Vec<u8> = truth
            .iter()
            .enumerate()
            .map(|(i, &t)| {
                if (i / 128 / 16 + i % 128 / 16) % 7 == 0 {
                    rng.random_range(0..slots)
                } else {
                    perm[t as usize]
                }
            })
            .collect();
        write_png(
            &pred_dir.join(format!("{stem}_mask.png")),
            128,
            128,
            png::ColorType::Grayscale,
            None,
            &pred,
        );
        let rgb = clevrtex_eval::resize::crop_resize_bilinear_rgb(&img, w, h, 128).expect("crop");
        let recon: Vec<u8> = rgb
            .iter()
            .map(|&v| (v as i32 + rng.random_range(-10..=10)).clamp(0, 255) as u8)
            .collect();
        write_png(
            &pred_dir.join(format!("{stem}_recon.png")),
            128,
            128,
            png::ColorType::Rgb,
            None,
            &recon,
        );
    });
    eprintln!("wrote {n} samples under {}", root.display());
}
