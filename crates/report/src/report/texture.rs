//! Per-image measurements that need the pixels, made on a capped sample of each variant:
//! how much each object stands out from the background ring around it (mean colour
//! difference in CIELAB, ΔE*76, and the distinctness tool's texture-feature distance), and
//! the depth range of the image.
//!
//! The ring is the background (mask id 0) within `max(2, W / 40)` pixels (8 at 320 px wide)
//! of the object, found with a separable square dilation of the object's mask.

use std::path::{Path, PathBuf};

use clevrtex_dataset::dataset::{self, Kind};
use clevrtex_dataset::layout;
use clevrtex_scene::Pass;
use image::RgbImage;

use crate::materials::stats::{distance, lab, region_features};
use crate::preview::{read_colour_png, read_pass_png};

use super::data::Sample;

/// One object's contrast to its surroundings.
#[derive(Debug, Clone, Copy)]
pub struct Contrast {
    /// ΔE*76 between the object's mean Lab colour and the ring's.
    pub delta_e: f64,
    /// Texture-feature distance (0 = identical; colour histogram plus gradient statistics).
    pub feature_distance: f64,
}

/// What one image gave.
#[derive(Debug, Clone, Default)]
pub struct ImageMeasures {
    pub contrasts: Vec<Contrast>,
    /// Nearest and farthest valid depth, metres (with a depth pass and its encoding).
    pub depth_range: Option<(f64, f64)>,
}

/// Measure one sample; passes it lacks give nothing. Its files are read under `root` (the
/// dataset's root, canonical) with the dataset reader: a pass file that is a link out of the
/// dataset, a FIFO or a device is not read and makes the sample a problem, like one that is
/// damaged.
pub fn measure(s: &Sample, root: &Path) -> anyhow::Result<ImageMeasures> {
    let mut out = ImageMeasures::default();
    let file = |p: Pass| -> anyhow::Result<Option<PathBuf>> {
        let path = s.dir.join(layout::pass_file(&s.stem, p));
        match dataset::classify(root, &path) {
            Kind::File => Ok(Some(path)),
            Kind::Skipped(why) if std::fs::symlink_metadata(&path).is_ok() => {
                anyhow::bail!("`{}` {why}", path.display())
            }
            _ => Ok(None),
        }
    };
    if let (Some(rgb), Some(mask)) = (file(Pass::Rgb)?, file(Pass::Mask)?) {
        let img = read_colour_png(root, &rgb)?;
        let m = read_pass_png(root, &mask, Pass::Mask)?;
        if (m.width, m.height) != img.dimensions() {
            anyhow::bail!(
                "`{}` is {}x{} but its mask `{}` is {}x{}",
                rgb.display(),
                img.width(),
                img.height(),
                mask.display(),
                m.width,
                m.height
            );
        }
        out.contrasts = contrasts(&img, &m.data, s.objects.len());
    }
    if let (Some((scale, background)), Some(depth)) = (s.depth_encoding, file(Pass::Depth)?) {
        let d = read_pass_png(root, &depth, Pass::Depth)?;
        let (lo, hi) = d
            .data
            .iter()
            .filter(|&&v| v != background && v != 0)
            .fold((u16::MAX, 0u16), |(lo, hi), &v| (lo.min(v), hi.max(v)));
        if hi >= lo {
            out.depth_range = Some((f64::from(lo) * scale, f64::from(hi) * scale));
        }
    }
    Ok(out)
}

/// Contrast of each object `1..=n` of `ids` to its background ring.
pub fn contrasts(img: &RgbImage, ids: &[u16], n: usize) -> Vec<Contrast> {
    let (w, h) = (img.width() as usize, img.height() as usize);
    let r = (w / 40).max(2);
    let mut out = Vec::new();
    for id in 1..=n as u16 {
        // The object's box, grown by the ring width.
        let (mut x0, mut y0, mut x1, mut y1) = (usize::MAX, usize::MAX, 0, 0);
        for (i, &v) in ids.iter().enumerate() {
            if v == id {
                let (x, y) = (i % w, i / w);
                x0 = x0.min(x);
                y0 = y0.min(y);
                x1 = x1.max(x);
                y1 = y1.max(y);
            }
        }
        if x0 == usize::MAX {
            continue;
        }
        let (bx0, by0) = (x0.saturating_sub(r), y0.saturating_sub(r));
        let (bx1, by1) = ((x1 + r).min(w - 1), (y1 + r).min(h - 1));
        let (bw, bh) = (bx1 - bx0 + 1, by1 - by0 + 1);
        let obj = |x: usize, y: usize| ids[(by0 + y) * w + bx0 + x] == id;
        // Dilate along rows, then columns, with running counts.
        let mut rows = vec![false; bw * bh];
        for y in 0..bh {
            let mut count = 0i64;
            for x in 0..(bw + r) {
                if x < bw && obj(x, y) {
                    count += 1;
                }
                if x > 2 * r && obj(x - 2 * r - 1, y) {
                    count -= 1;
                }
                if x >= r && x - r < bw {
                    rows[y * bw + x - r] = count > 0;
                }
            }
        }
        let mut ring = vec![false; bw * bh];
        for x in 0..bw {
            let mut count = 0i64;
            for y in 0..(bh + r) {
                if y < bh && rows[y * bw + x] {
                    count += 1;
                }
                if y > 2 * r && rows[(y - 2 * r - 1) * bw + x] {
                    count -= 1;
                }
                if y >= r && y - r < bh {
                    let yy = y - r;
                    ring[yy * bw + x] = count > 0 && ids[(by0 + yy) * w + bx0 + x] == 0;
                }
            }
        }
        let in_obj = |x: u32, y: u32| {
            let (x, y) = (x as usize, y as usize);
            x >= bx0 && x <= bx1 && y >= by0 && y <= by1 && ids[y * w + x] == id
        };
        let in_ring = |x: u32, y: u32| {
            let (x, y) = (x as usize, y as usize);
            x >= bx0 && x <= bx1 && y >= by0 && y <= by1 && ring[(y - by0) * bw + x - bx0]
        };
        let mean_lab = |inside: &dyn Fn(u32, u32) -> bool| {
            let (mut s, mut c) = ([0.0f64; 3], 0.0);
            for y in by0..=by1 {
                for x in bx0..=bx1 {
                    if inside(x as u32, y as u32) {
                        let l = lab(img.get_pixel(x as u32, y as u32).0);
                        (0..3).for_each(|k| s[k] += l[k]);
                        c += 1.0;
                    }
                }
            }
            (s.map(|v| v / f64::max(c, 1.0)), c)
        };
        let (lo, no) = mean_lab(&in_obj);
        let (lr, nr) = mean_lab(&in_ring);
        if no < 16.0 || nr < 16.0 {
            continue;
        }
        let delta_e =
            ((lo[0] - lr[0]).powi(2) + (lo[1] - lr[1]).powi(2) + (lo[2] - lr[2]).powi(2)).sqrt();
        let feature_distance = distance(
            &region_features(img, in_obj),
            &region_features(img, in_ring),
        );
        out.push(Contrast {
            delta_e,
            feature_distance,
        });
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_red_square_on_grey_stands_out_and_a_grey_one_does_not() {
        let (w, h) = (64u32, 48u32);
        let mut ids = vec![0u16; (w * h) as usize];
        for y in 10..30 {
            for x in 10..30 {
                ids[(y * w + x) as usize] = 1;
            }
        }
        let grey = image::Rgb([128, 128, 128]);
        let red = RgbImage::from_fn(w, h, |x, y| {
            if ids[(y * w + x) as usize] == 1 {
                image::Rgb([200, 30, 30])
            } else {
                grey
            }
        });
        let c = contrasts(&red, &ids, 1);
        assert_eq!(c.len(), 1);
        assert!(c[0].delta_e > 40.0, "{c:?}");
        let flat = RgbImage::from_pixel(w, h, grey);
        let c = contrasts(&flat, &ids, 1);
        assert!(c[0].delta_e < 1e-9 && c[0].feature_distance < 1e-9, "{c:?}");
    }
}
