//! Texture statistics of flat-lit tile renders, for the distinctness check.
//!
//! Features: a 4x4x4 colour histogram, gradient energy at three scales (1, 2 and 4 pixel
//! boxes) and the share of gradient energy along four orientations. The distance between
//! two materials is half the L1 distance of the histograms (0..1) plus the mean relative
//! difference of the texture features (0..1). Also the sRGB to CIELAB conversion ([`lab`])
//! shared by the report and the dataset figures.

use std::path::Path;

/// The features of one tile.
#[derive(Debug, Clone, PartialEq)]
pub struct Features {
    /// Normalised 64-bin RGB histogram.
    pub histogram: Vec<f64>,
    /// Mean gradient magnitude at three scales, then the orientation shares (4).
    pub texture: Vec<f64>,
}

/// Compute the features of a PNG tile.
pub fn features(path: &Path) -> Result<Features, image::ImageError> {
    let img = image::open(path)?.to_rgb8();
    Ok(region_features(&img, |_, _| true))
}

/// The features of the pixels of `img` where `inside(x, y)`: the histogram counts those
/// pixels, the gradients only boxes whose pixels are all inside (and their right and lower
/// neighbours), so a region's features do not see its surroundings. With every pixel inside,
/// these are the tile's features.
pub fn region_features(img: &image::RgbImage, inside: impl Fn(u32, u32) -> bool) -> Features {
    let (w, h) = img.dimensions();
    let mut histogram = vec![0.0; 64];
    let mut lum = vec![0.0f64; (w * h) as usize];
    let mut mask = vec![false; (w * h) as usize];
    let mut n = 0.0f64;
    for (x, y, p) in img.enumerate_pixels() {
        if !inside(x, y) {
            continue;
        }
        let [r, g, b] = p.0;
        let bin = (r as usize / 64) * 16 + (g as usize / 64) * 4 + b as usize / 64;
        histogram[bin] += 1.0;
        n += 1.0;
        mask[(y * w + x) as usize] = true;
        lum[(y * w + x) as usize] =
            (0.2126 * r as f64 + 0.7152 * g as f64 + 0.0722 * b as f64) / 255.0;
    }
    histogram.iter_mut().for_each(|v| *v /= n.max(1.0));
    let mut texture = Vec::new();
    let mut orient = [0.0f64; 4];
    for scale in [1usize, 2, 4] {
        let (sw, sh) = (w as usize / scale, h as usize / scale);
        let mut small = vec![0.0; sw * sh];
        let mut full = vec![true; sw * sh];
        for y in 0..sh * scale {
            for x in 0..sw * scale {
                small[(y / scale) * sw + x / scale] += lum[y * w as usize + x];
                full[(y / scale) * sw + x / scale] &= mask[y * w as usize + x];
            }
        }
        small.iter_mut().for_each(|v| *v /= (scale * scale) as f64);
        let mut energy = 0.0f64;
        let mut count = 0.0f64;
        for y in 0..sh.saturating_sub(1) {
            for x in 0..sw.saturating_sub(1) {
                if !(full[y * sw + x] && full[y * sw + x + 1] && full[(y + 1) * sw + x]) {
                    continue;
                }
                let c = small[y * sw + x];
                let gx = small[y * sw + x + 1] - c;
                let gy = small[(y + 1) * sw + x] - c;
                energy += (gx * gx + gy * gy).sqrt();
                count += 1.0;
                if scale == 2 {
                    let s = std::f64::consts::FRAC_1_SQRT_2;
                    orient[0] += gx.abs();
                    orient[1] += ((gx + gy) * s).abs();
                    orient[2] += gy.abs();
                    orient[3] += ((gx - gy) * s).abs();
                }
            }
        }
        texture.push(energy / count.max(1.0));
    }
    let total: f64 = orient.iter().sum::<f64>().max(1e-12);
    texture.extend(orient.iter().map(|o| o / total));
    Features { histogram, texture }
}

/// Distance between two feature sets (0 = identical).
pub fn distance(a: &Features, b: &Features) -> f64 {
    let hist: f64 = a
        .histogram
        .iter()
        .zip(&b.histogram)
        .map(|(x, y)| (x - y).abs())
        .sum::<f64>()
        * 0.5;
    let tex: f64 = a
        .texture
        .iter()
        .zip(&b.texture)
        .map(|(x, y)| (x - y).abs() / (x + y + 1e-3))
        .sum::<f64>()
        / a.texture.len() as f64;
    hist + tex
}

/// How distinct the materials of a batch are, from two renders of each with different
/// `random` seeds (`a` and `b`): the same material's distance between its two renders is the
/// yardstick, so two different materials closer than the median of those could pass for one.
#[derive(Debug, Clone, PartialEq)]
pub struct Distinctness {
    /// Per material: the nearest other one (itself when alone) and the distance to it.
    pub nearest: Vec<(usize, f64)>,
    /// Per material: the distance between its two renders.
    pub self_distance: Vec<f64>,
    /// The median self-distance.
    pub threshold: f64,
    /// The largest self-distance.
    pub max_self: f64,
    /// The smallest distance between different materials.
    pub min_inter: f64,
    /// Pairs `(i, j)`, `i < j`, of materials closer than `threshold`, with their distance.
    pub near: Vec<(usize, usize, f64)>,
}

/// The [`Distinctness`] of materials with features `a[i]` and `b[i]`. Needs at least one.
pub fn distinctness(a: &[Features], b: &[Features]) -> Distinctness {
    let intra: Vec<f64> = (0..a.len()).map(|i| distance(&a[i], &b[i])).collect();
    let mut sorted = intra.clone();
    sorted.sort_by(f64::total_cmp);
    let threshold = sorted[sorted.len() / 2];
    let mut nearest = Vec::new();
    let mut near = Vec::new();
    let mut min_inter = f64::INFINITY;
    for i in 0..a.len() {
        let (j, d) = (0..a.len())
            .filter(|&j| j != i)
            .map(|j| (j, distance(&a[i], &a[j])))
            .min_by(|x, y| x.1.total_cmp(&y.1))
            .unwrap_or((i, f64::NAN));
        min_inter = min_inter.min(d);
        nearest.push((j, d));
        if d < threshold && i < j {
            near.push((i, j, d));
        }
    }
    Distinctness {
        nearest,
        self_distance: intra,
        threshold,
        max_self: sorted[sorted.len() - 1],
        min_inter,
        near,
    }
}

use clevrtex_materials::srgb_to_linear;

/// CIELAB (D65) of an sRGB pixel.
pub fn lab(p: [u8; 3]) -> [f64; 3] {
    let [r, g, b] = p.map(srgb_to_linear);
    let x = (0.4124 * r + 0.3576 * g + 0.1805 * b) / 0.95047;
    let y = 0.2126 * r + 0.7152 * g + 0.0722 * b;
    let z = (0.0193 * r + 0.1192 * g + 0.9505 * b) / 1.08883;
    let f = |t: f64| {
        if t > 216.0 / 24389.0 {
            t.cbrt()
        } else {
            (24389.0 / 27.0 * t + 16.0) / 116.0
        }
    };
    let (fx, fy, fz) = (f(x), f(y), f(z));
    [116.0 * fy - 16.0, 500.0 * (fx - fy), 200.0 * (fy - fz)]
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn near_copies_are_closer_than_the_median_self_distance() {
        let tile = |v: u8, stripe: u32| {
            let img = image::RgbImage::from_fn(32, 32, |x, _| {
                image::Rgb(if (x / stripe).is_multiple_of(2) {
                    [v, v, v]
                } else {
                    [0, 0, v]
                })
            });
            region_features(&img, |_, _| true)
        };
        // a and a' are near-copies; c differs in colour and pattern.
        let a = [tile(200, 2), tile(201, 2), tile(90, 8)];
        let b = [tile(198, 2), tile(203, 2), tile(95, 8)];
        let d = distinctness(&a, &b);
        assert_eq!(d.nearest[0].0, 1);
        assert_eq!(d.nearest[1].0, 0);
        assert_eq!(d.near.len(), 1);
        assert_eq!((d.near[0].0, d.near[0].1), (0, 1));
        assert!(d.min_inter < d.threshold && d.max_self >= d.threshold);
    }

    #[test]
    fn lab_of_white_and_black() {
        let w = lab([255, 255, 255]);
        assert!((w[0] - 100.0).abs() < 0.01 && w[1].abs() < 0.05 && w[2].abs() < 0.05);
        assert!(lab([0, 0, 0])[0].abs() < 1e-9);
    }

    #[test]
    fn a_region_has_the_features_of_the_same_pixels_cut_out() {
        // A textured image: stripes on the left half, noise-like values on the right.
        let img = image::RgbImage::from_fn(48, 32, |x, y| {
            let v = if x < 24 {
                if (x / 3) % 2 == 0 {
                    200
                } else {
                    40
                }
            } else {
                ((x * 37 + y * 91) % 251) as u8
            };
            image::Rgb([v, v / 2, 255 - v])
        });
        let left = image::imageops::crop_imm(&img, 0, 0, 24, 32).to_image();
        let region = region_features(&img, |x, _| x < 24);
        let cut = region_features(&left, |_, _| true);
        assert_eq!(region, cut);
        // And it differs from the whole image's.
        assert!(distance(&region, &region_features(&img, |_, _| true)) > 0.1);
    }
}
