//! The per-region computations of the dataset figures of `materials measure` (described in
//! [`super::figures`]): the kept pixels, the albedo spread, the interior/boundary gradient
//! ratio, the scale ratio and the median. Pure functions of pixel buffers; the reading of a
//! dataset is `figures.rs`.

use std::collections::BTreeMap;

use clevrtex_eval::resize::{crop_resize_bilinear_rgb, crop_resize_nearest, EVAL_SIDE};

use super::stats::lab;

/// Regions with fewer kept pixels are skipped.
pub const MIN_KEPT: usize = 400;
/// Regions whose L varies less (std) are skipped by the scale ratio.
pub const MIN_STD_L: f64 = 0.5;
/// Pixels whose 5x5 neighbourhood lies inside the image and holds one id.
pub fn kept(ids: &[u32], w: usize, h: usize) -> Vec<bool> {
    uniform(ids, w, h, 2)
}

/// Pixels whose `(2r+1)^2` neighbourhood lies inside the image and holds one id.
fn uniform(ids: &[u32], w: usize, h: usize, r: usize) -> Vec<bool> {
    let mut out = vec![false; w * h];
    if w <= 2 * r || h <= 2 * r {
        return out;
    }
    for y in r..h - r {
        for x in r..w - r {
            let id = ids[y * w + x];
            out[y * w + x] = (y - r..=y + r).all(|yy| {
                ids[yy * w + x - r..=yy * w + x + r]
                    .iter()
                    .all(|&v| v == id)
            });
        }
    }
    out
}

fn lab_image(rgb: &[u8]) -> Vec<[f64; 3]> {
    rgb.chunks_exact(3)
        .map(|p| lab([p[0], p[1], p[2]]))
        .collect()
}

/// The albedo spread of every region with at least [`MIN_KEPT`] kept pixels, by id.
pub fn albedo_spread(albedo: &[u8], ids: &[u32], w: usize, h: usize) -> BTreeMap<u32, f64> {
    let keep = kept(ids, w, h);
    let lab = lab_image(albedo);
    let mut acc: BTreeMap<u32, (f64, [f64; 3], [f64; 3])> = BTreeMap::new();
    for i in (0..w * h).filter(|&i| keep[i]) {
        let e = acc.entry(ids[i]).or_insert((0.0, [0.0; 3], [0.0; 3]));
        e.0 += 1.0;
        for (k, v) in lab[i].iter().enumerate() {
            e.1[k] += v;
            e.2[k] += v * v;
        }
    }
    acc.into_iter()
        .filter(|(_, (n, _, _))| *n >= MIN_KEPT as f64)
        .map(|(id, (n, s, ss))| {
            let var: f64 = (0..3)
                .map(|k| (ss[k] / n - (s[k] / n).powi(2)).max(0.0))
                .sum();
            (id, var.sqrt())
        })
        .collect()
}

/// The gradient figures of one image.
#[derive(Debug, Clone, PartialEq)]
pub struct Gradient {
    /// Mean gradient inside regions over the mean on boundaries (`None` without boundary
    /// pixels or with a zero boundary gradient).
    pub ratio: Option<f64>,
    /// Per region: its interior mean gradient over the image's boundary mean.
    pub regions: BTreeMap<u32, f64>,
}

/// The interior/boundary gradient ratio of an RGB image and its mask of `w x h`, after the
/// evaluator's crop and resize to 128x128.
pub fn gradient_ratio(rgb: &[u8], ids: &[u32], w: usize, h: usize) -> Option<Gradient> {
    let img = crop_resize_bilinear_rgb(rgb, w, h, EVAL_SIDE)?;
    let ids = crop_resize_nearest(ids, w, h, EVAL_SIDE)?;
    Some(gradient_ratio_at(&img, &ids, EVAL_SIDE))
}

/// [`gradient_ratio`] of an `n x n` image as it is (no crop or resize).
pub fn gradient_ratio_at(rgb: &[u8], ids: &[u32], n: usize) -> Gradient {
    let lum: Vec<f64> = rgb
        .chunks_exact(3)
        .map(|p| 0.299 * f64::from(p[0]) + 0.587 * f64::from(p[1]) + 0.114 * f64::from(p[2]))
        .collect();
    let interior = uniform(ids, n, n, 3);
    let (mut bsum, mut bcount) = (0.0, 0.0);
    let mut inside: BTreeMap<u32, (f64, f64)> = BTreeMap::new();
    for y in 1..n.saturating_sub(1) {
        for x in 1..n - 1 {
            let i = y * n + x;
            let gx = (lum[i + 1] - lum[i - 1]) / 2.0;
            let gy = (lum[i + n] - lum[i - n]) / 2.0;
            let g = (gx * gx + gy * gy).sqrt();
            let id = ids[i];
            let boundary = (y - 1..=y + 1).any(|yy| {
                ids[yy * n + x - 1..=yy * n + x + 1]
                    .iter()
                    .any(|&v| v != id)
            });
            if boundary {
                bsum += g;
                bcount += 1.0;
            } else if interior[i] {
                let e = inside.entry(id).or_insert((0.0, 0.0));
                e.0 += g;
                e.1 += 1.0;
            }
        }
    }
    let bmean = bsum / bcount;
    if bcount == 0.0 || bmean <= 0.0 {
        return Gradient {
            ratio: None,
            regions: BTreeMap::new(),
        };
    }
    let (isum, icount) = inside
        .values()
        .fold((0.0, 0.0), |(s, c), (gs, gc)| (s + gs, c + gc));
    Gradient {
        ratio: (icount > 0.0).then(|| isum / icount / bmean),
        regions: inside
            .into_iter()
            .map(|(id, (s, c))| (id, s / c / bmean))
            .collect(),
    }
}

/// The scale figures of one image.
#[derive(Debug, Clone, PartialEq)]
pub struct Scale {
    /// `q = D(1) / D(4)` of every region measured, by id.
    pub q: BTreeMap<u32, f64>,
    /// The backdrop's `q` over the median `q` of the objects (both needed).
    pub ratio: Option<f64>,
}

/// The scale figures of an albedo image and its mask.
pub fn scale_ratio(albedo: &[u8], ids: &[u32], w: usize, h: usize) -> Scale {
    let keep = kept(ids, w, h);
    let l: Vec<f64> = lab_image(albedo).iter().map(|p| p[0]).collect();
    let mut count: BTreeMap<u32, (f64, f64, f64)> = BTreeMap::new();
    for i in (0..w * h).filter(|&i| keep[i]) {
        let e = count.entry(ids[i]).or_insert((0.0, 0.0, 0.0));
        e.0 += 1.0;
        e.1 += l[i];
        e.2 += l[i] * l[i];
    }
    let mut q = BTreeMap::new();
    for (&id, &(n, s, ss)) in &count {
        if n < MIN_KEPT as f64 || (ss / n - (s / n).powi(2)).max(0.0).sqrt() < MIN_STD_L {
            continue;
        }
        let d = |r: usize| {
            let (mut sum, mut c) = (0.0, 0.0);
            for y in 0..h {
                for x in 0..w {
                    let i = y * w + x;
                    if !keep[i] || ids[i] != id {
                        continue;
                    }
                    for j in [(x + r < w).then(|| i + r), (y + r < h).then(|| i + r * w)]
                        .into_iter()
                        .flatten()
                    {
                        if keep[j] && ids[j] == id {
                            sum += (l[i] - l[j]).powi(2);
                            c += 1.0;
                        }
                    }
                }
            }
            (c > 0.0).then(|| sum / c)
        };
        if let (Some(d1), Some(d4)) = (d(1), d(4)) {
            if d4 > 0.0 {
                q.insert(id, d1 / d4);
            }
        }
    }
    let objects: Vec<f64> = q
        .iter()
        .filter(|(&id, _)| id != 0)
        .map(|(_, &v)| v)
        .collect();
    let ratio = match (q.get(&0), median(&objects)) {
        (Some(&b), Some(m)) if m > 0.0 => Some(b / m),
        _ => None,
    };
    Scale { q, ratio }
}

/// The median of `v` (the mean of the middle two for an even count); `None` when empty.
pub fn median(v: &[f64]) -> Option<f64> {
    let mut s: Vec<f64> = v.iter().copied().filter(|x| x.is_finite()).collect();
    if s.is_empty() {
        return None;
    }
    s.sort_by(f64::total_cmp);
    let n = s.len();
    Some(if n % 2 == 1 {
        s[n / 2]
    } else {
        (s[n / 2 - 1] + s[n / 2]) / 2.0
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn grey(v: &[u8]) -> Vec<u8> {
        v.iter().flat_map(|&g| [g, g, g]).collect()
    }

    #[test]
    fn a_constant_region_has_spread_zero_and_noise_does_not() {
        let (w, h) = (40, 40);
        let ids = vec![3u32; w * h];
        let flat = grey(&vec![120; w * h]);
        let s = albedo_spread(&flat, &ids, w, h);
        assert!(s[&3].abs() < 1e-4, "{s:?}");
        // Two greys in equal shares: spread = half the L difference.
        let two: Vec<u8> = (0..w * h)
            .map(|i| if i % 2 == 0 { 50 } else { 200 })
            .collect();
        let s = albedo_spread(&grey(&two), &ids, w, h);
        let (l0, l1) = (lab([50; 3])[0], lab([200; 3])[0]);
        // Kept pixels: 36x36 = 1296, an even count of each.
        assert!((s[&3] - (l1 - l0) / 2.0).abs() < 1e-3, "{s:?}");
    }

    #[test]
    fn only_pixels_away_from_other_ids_count_and_small_regions_are_skipped() {
        let (w, h) = (30, 30);
        // id 1 on the left half, 2 on the right; kept: 2 px from any other id or the border.
        let ids: Vec<u32> = (0..w * h).map(|i| if i % w < 15 { 1 } else { 2 }).collect();
        let k = kept(&ids, w, h);
        assert_eq!(k.iter().filter(|&&b| b).count(), 2 * 11 * 26);
        assert!(!k[5 * w + 13] && k[5 * w + 12] && !k[5 * w + 1]);
        // 286 kept pixels each: under 400, skipped.
        assert!(albedo_spread(&grey(&vec![9; w * h]), &ids, w, h).is_empty());
    }

    #[test]
    fn a_ramp_has_ratio_one_and_a_step_ratio_zero() {
        let n = 32;
        let ids: Vec<u32> = (0..n * n).map(|i| if i % n < 16 { 0 } else { 1 }).collect();
        // The same gradient everywhere.
        let ramp: Vec<u8> = (0..n * n).map(|i| (i % n * 4) as u8).collect();
        let g = gradient_ratio_at(&grey(&ramp), &ids, n);
        assert!((g.ratio.unwrap() - 1.0).abs() < 1e-9, "{g:?}");
        assert!((g.regions[&0] - 1.0).abs() < 1e-9 && (g.regions[&1] - 1.0).abs() < 1e-9);
        // Flat regions with a step between them: nothing inside, all on the boundary.
        let step: Vec<u8> = (0..n * n)
            .map(|i| if i % n < 16 { 40 } else { 200 })
            .collect();
        let g = gradient_ratio_at(&grey(&step), &ids, n);
        assert_eq!(g.ratio, Some(0.0));
        // One region: no boundary, no ratio.
        let g = gradient_ratio_at(&grey(&ramp), &[5; 32 * 32], n);
        assert_eq!(g.ratio, None);
    }

    #[test]
    fn gradient_ratio_crops_and_resizes_like_the_evaluator() {
        // 160x160: the crop is 128 px, resized to 128 (unchanged), at offset 16.
        let n = 160;
        let ids: Vec<u32> = (0..n * n).map(|i| u32::from(i % n >= 80)).collect();
        let ramp: Vec<u8> = (0..n * n).map(|i| (i % n) as u8).collect();
        let g = gradient_ratio(&grey(&ramp), &ids, n, n).unwrap();
        assert!((g.ratio.unwrap() - 1.0).abs() < 1e-9, "{g:?}");
    }

    #[test]
    fn scale_ratio_of_stripes_and_of_twice_as_coarse_noise() {
        // Vertical stripes of period 8 (4 px bars) over 64x64: of the kept pixels' pairs
        // (x, y in 2..=61), 15 of 59 horizontal pairs a row differ at distance 1 and all 56
        // at distance 4; vertical pairs never do. q = (900/7080) / (3360/6720) = 0.2542.
        let (w, h) = (64, 64);
        let v: Vec<u8> = (0..w * h)
            .map(|i| if i % w % 8 < 4 { 60 } else { 180 })
            .collect();
        let s = scale_ratio(&grey(&v), &vec![0; w * h], w, h);
        assert!((s.q[&0] - 900.0 / 7080.0 / 0.5).abs() < 1e-9, "{s:?}");
        assert_eq!(s.ratio, None); // no objects
                                   // Pixel noise on the backdrop (left), the same noise in 2x2 blocks on the object
                                   // (right): q = 1 and 1/2 in expectation, so the ratio is about 2; with the same
                                   // grain on both, about 1. A flat region is skipped (std L under 0.5).
        let noise = |x: usize, y: usize| {
            let h = (x as u64 * 0x9e37_79b9 + y as u64 * 0x85eb_ca6b) ^ 0x2545_f491;
            let h = h.wrapping_mul(0xff51_afd7_ed55_8ccd);
            (h >> 56) as u8
        };
        let (w, h) = (160, 80);
        let ids: Vec<u32> = (0..w * h).map(|i| u32::from(i % w >= 80)).collect();
        let img = |coarse: bool, flat: bool| {
            let v: Vec<u8> = (0..w * h)
                .map(|i| {
                    let (x, y) = (i % w, i / w);
                    match (ids[i], coarse, flat) {
                        (1, _, true) => 100,
                        (1, true, _) => noise(x / 2, y / 2),
                        _ => noise(x, y),
                    }
                })
                .collect();
            grey(&v)
        };
        let r = scale_ratio(&img(true, false), &ids, w, h).ratio.unwrap();
        assert!((r - 2.0).abs() < 0.3, "{r}");
        let r = scale_ratio(&img(false, false), &ids, w, h).ratio.unwrap();
        assert!((r - 1.0).abs() < 0.15, "{r}");
        let s = scale_ratio(&img(false, true), &ids, w, h);
        assert!(s.q.contains_key(&0) && !s.q.contains_key(&1) && s.ratio.is_none());
    }

    #[test]
    fn medians() {
        assert_eq!(median(&[]), None);
        assert_eq!(median(&[3.0, 1.0, 2.0]), Some(2.0));
        assert_eq!(median(&[4.0, 1.0, 2.0, 3.0]), Some(2.5));
    }
}
