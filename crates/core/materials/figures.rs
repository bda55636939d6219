//! `clevrtex materials measure`: three figures of a rendered dataset that tell procedural
//! materials from the photographs they stand in for (issue 23; `docs/materials.md`,
//! "Measuring a dataset"):
//!
//! - **albedo spread**: per region (each object id, and the background 0) of the albedo pass
//!   at native size, over the pixels whose 5x5 neighbourhood is one id (regions under 400
//!   such pixels skipped): sRGB to CIELAB (D65), `sqrt(var L + var a + var b)`;
//! - **interior/boundary gradient ratio**: the RGB image centre-cropped and resized as the
//!   evaluator does (128x128, Pillow's bilinear; the mask nearest); luminance
//!   `0.299 R + 0.587 G + 0.114 B` (0..255); gradient magnitude by central differences;
//!   boundary pixels have more than one id in their 3x3 neighbourhood, interior pixels one id
//!   in their 7x7; the ratio is the mean gradient inside over the mean on boundaries (per
//!   region: the region's interior mean over the image's boundary mean);
//! - **scale ratio** (meant for `camo`): on the albedo, per region as above (regions with
//!   std L < 0.5 skipped), `D(r)` = mean squared difference of L between kept pixels of the
//!   region `r` apart (horizontal and vertical pairs); `q = D(1) / D(4)`; per image, the
//!   backdrop's `q` over the median `q` of the objects.
//!
//! A dataset is untrusted input: files are read through `clevrtex_render::dataset` (links
//! only inside the dataset, regular files only, a size cap), a PNG's header size is checked
//! before anything is decoded, and every problem is an error naming the file.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use anyhow::{anyhow, bail, Context};
use clevrtex_eval::resize::{crop_resize_bilinear_rgb, crop_resize_nearest, EVAL_SIDE};
use clevrtex_render::dataset;
use clevrtex_scene::{layout, Pass};
use rayon::prelude::*;

use super::stats::lab;

/// Regions with fewer kept pixels are skipped.
pub const MIN_KEPT: usize = 400;
/// Regions whose L varies less (std) are skipped by the scale ratio.
pub const MIN_STD_L: f64 = 0.5;
/// The largest image measured (width and height), checked in the PNG header.
pub const MAX_SIDE: u32 = 8192;
/// The largest metadata file read.
const MAX_METADATA_BYTES: u64 = 16 << 20;

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

/// What one sample gave, with its regions' materials.
#[derive(Debug, Clone)]
pub struct SampleFigures {
    pub variant: String,
    pub stem: String,
    /// Material of region id (0: the backdrop's `ground_material`).
    pub materials: BTreeMap<u32, String>,
    pub spread: BTreeMap<u32, f64>,
    pub gradient: Option<Gradient>,
    pub scale: Scale,
}

/// One PNG of a sample, decoded after its header's size was checked.
struct Png {
    width: usize,
    height: usize,
    channels: usize,
    data: Vec<u16>,
}

/// The (width, height) of a PNG's IHDR, if it is one.
fn png_size(bytes: &[u8]) -> Option<(u32, u32)> {
    if bytes.len() < 24 || &bytes[..8] != b"\x89PNG\r\n\x1a\n" || &bytes[12..16] != b"IHDR" {
        return None;
    }
    let be = |o: usize| u32::from_be_bytes([bytes[o], bytes[o + 1], bytes[o + 2], bytes[o + 3]]);
    Some((be(16), be(20)))
}

fn read_png(root: &Path, path: &Path) -> anyhow::Result<Png> {
    let bytes = dataset::read(root, path, dataset::MAX_FILE_BYTES)
        .map_err(|why| anyhow!("`{}` {why}", path.display()))?;
    let Some((w, h)) = png_size(&bytes) else {
        bail!("`{}` is not a PNG", path.display());
    };
    if w == 0 || h == 0 || w > MAX_SIDE || h > MAX_SIDE {
        bail!(
            "`{}` claims {w}x{h} pixels (at most {MAX_SIDE}x{MAX_SIDE} are measured)",
            path.display()
        );
    }
    let p = clevrtex_render::post::decode_png_bytes(&bytes, path)
        .map_err(|e| anyhow!("{}", e.to_string().lines().next().unwrap_or("bad PNG")))
        .with_context(|| format!("cannot decode `{}`", path.display()))?;
    if p.bits != 8 {
        bail!(
            "`{}` is a {}-bit PNG, expected 8-bit",
            path.display(),
            p.bits
        );
    }
    Ok(Png {
        width: p.width as usize,
        height: p.height as usize,
        channels: p.channels,
        data: p.data,
    })
}

fn rgb8(root: &Path, path: &Path) -> anyhow::Result<(usize, usize, Vec<u8>)> {
    let p = read_png(root, path)?;
    let px = p.width * p.height;
    let data: Vec<u8> = match p.channels {
        3 | 4 => p
            .data
            .chunks_exact(p.channels)
            .flat_map(|c| [c[0] as u8, c[1] as u8, c[2] as u8])
            .collect(),
        n => bail!("`{}` has {n} channels, expected RGB", path.display()),
    };
    if data.len() != px * 3 {
        bail!("`{}` is truncated", path.display());
    }
    Ok((p.width, p.height, data))
}

/// Measure the sample `stem` in `dir` (under the dataset root `root`).
pub fn measure_sample(
    root: &Path,
    dir: &Path,
    variant: &str,
    stem: &str,
) -> anyhow::Result<SampleFigures> {
    let meta_path = dir.join(layout::metadata_file(stem));
    let bytes = dataset::read(root, &meta_path, MAX_METADATA_BYTES)
        .map_err(|why| anyhow!("`{}` {why}", meta_path.display()))?;
    let meta: serde_json::Value = serde_json::from_slice(&bytes)
        .with_context(|| format!("`{}` is not valid metadata", meta_path.display()))?;
    let Some(objects) = meta["objects"].as_array() else {
        bail!("`{}` has no `objects` list", meta_path.display());
    };
    let mut materials = BTreeMap::new();
    materials.insert(
        0,
        meta["ground_material"].as_str().unwrap_or("?").to_string(),
    );
    for (i, o) in objects.iter().enumerate().take(255) {
        let m = o["material"].as_str().unwrap_or("?").to_string();
        materials.insert(i as u32 + 1, m);
    }
    let mask_path = dir.join(layout::pass_file(stem, Pass::Mask));
    let mask = read_png(root, &mask_path)?;
    if mask.channels != 1 {
        bail!(
            "`{}` has {} channels, expected a palette or grey mask",
            mask_path.display(),
            mask.channels
        );
    }
    let (w, h) = (mask.width, mask.height);
    let ids: Vec<u32> = mask.data.iter().map(|&v| u32::from(v)).collect();
    if ids.len() != w * h {
        bail!("`{}` is truncated", mask_path.display());
    }
    let same_size = |path: &Path, pw: usize, ph: usize| {
        if (pw, ph) == (w, h) {
            Ok(())
        } else {
            Err(anyhow!(
                "`{}` is {pw}x{ph}, its mask {w}x{h}",
                path.display()
            ))
        }
    };
    let rgb_path = dir.join(layout::pass_file(stem, Pass::Rgb));
    let gradient = if rgb_path.exists() {
        let (rw, rh, rgb) = rgb8(root, &rgb_path)?;
        same_size(&rgb_path, rw, rh)?;
        gradient_ratio(&rgb, &ids, w, h)
    } else {
        None
    };
    let albedo_path = dir.join(layout::pass_file(stem, Pass::Albedo));
    let (spread, scale) = if albedo_path.exists() {
        let (aw, ah, albedo) = rgb8(root, &albedo_path)?;
        same_size(&albedo_path, aw, ah)?;
        (
            albedo_spread(&albedo, &ids, w, h),
            scale_ratio(&albedo, &ids, w, h),
        )
    } else {
        (
            BTreeMap::new(),
            Scale {
                q: BTreeMap::new(),
                ratio: None,
            },
        )
    };
    Ok(SampleFigures {
        variant: variant.to_string(),
        stem: stem.to_string(),
        materials,
        spread,
        gradient,
        scale,
    })
}

/// One sample found: (variant, stem, folder).
pub type Found = (String, String, PathBuf);

/// The dataset's canonical root and its samples (found by the one read side of a dataset,
/// `clevrtex_scene::dataset::Dataset::open`): the `--out` of `generate` or one
/// `clevrtex_<variant>` folder.
pub fn find_samples(dir: &Path) -> anyhow::Result<(PathBuf, Vec<Found>)> {
    let hint =
        "hint: pass the `--out` folder of `clevrtex generate` or one `clevrtex_<variant>` folder";
    if !dir.is_dir() {
        bail!("dataset folder `{}` does not exist\n{hint}", dir.display());
    }
    let ds = clevrtex_scene::dataset::Dataset::open(dir).map_err(|e| match e {
        clevrtex_scene::dataset::DatasetError::Unreadable { cause, .. } => {
            anyhow::Error::new(cause).context(format!("cannot read `{}`", dir.display()))
        }
        other => other.into(),
    })?;
    let mut out = Vec::new();
    for vd in &ds.variants {
        if let Some((d, e)) = vd.unreadable.first() {
            return Err(anyhow::anyhow!("{e}").context(format!("cannot read `{}`", d.display())));
        }
        for s in vd.samples.iter().filter(|s| s.has_metadata()) {
            out.push((s.variant.clone(), s.stem.clone(), s.dir.clone()));
        }
    }
    out.sort();
    if out.is_empty() {
        bail!(
            "no samples (`CLEVRTEX_<variant>_<index>.json`) under `{}`\n{hint}",
            dir.display()
        );
    }
    Ok((ds.root, out))
}

/// Measure every sample under `dir`, in parallel.
pub fn measure_dataset(dir: &Path) -> anyhow::Result<Vec<SampleFigures>> {
    let (root, samples) = find_samples(dir)?;
    samples
        .par_iter()
        .map(|(variant, stem, sub)| measure_sample(&root, sub, variant, stem))
        .collect()
}

/// The figures gathered per key (a variant or a material).
#[derive(Debug, Clone, Default)]
pub struct Summary {
    pub images: usize,
    pub object_spread: Vec<f64>,
    pub background_spread: Vec<f64>,
    /// Per image (variants) or per region (materials).
    pub gradient: Vec<f64>,
    /// Per image (variants) or the region's `q` (materials).
    pub scale: Vec<f64>,
}

/// Per variant and per material summaries of measured samples.
pub fn summarise(
    samples: &[SampleFigures],
) -> (BTreeMap<String, Summary>, BTreeMap<String, Summary>) {
    let mut variants: BTreeMap<String, Summary> = BTreeMap::new();
    let mut materials: BTreeMap<String, Summary> = BTreeMap::new();
    for s in samples {
        let v = variants.entry(s.variant.clone()).or_default();
        v.images += 1;
        let material = |id: &u32| s.materials.get(id).cloned().unwrap_or_else(|| "?".into());
        for (id, &sp) in &s.spread {
            let m = materials.entry(material(id)).or_default();
            if *id == 0 {
                v.background_spread.push(sp);
                m.background_spread.push(sp);
            } else {
                v.object_spread.push(sp);
                m.object_spread.push(sp);
            }
        }
        if let Some(g) = &s.gradient {
            v.gradient.extend(g.ratio);
            for (id, &r) in &g.regions {
                materials.entry(material(id)).or_default().gradient.push(r);
            }
        }
        v.scale.extend(s.scale.ratio);
        for (id, &q) in &s.scale.q {
            materials.entry(material(id)).or_default().scale.push(q);
        }
    }
    (variants, materials)
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

    #[test]
    fn bad_files_are_errors_naming_the_file() {
        let d = tempfile::tempdir().unwrap();
        let sub = d.path().join("clevrtex_full/0");
        std::fs::create_dir_all(&sub).unwrap();
        let stem = "CLEVRTEX_full_000000";
        std::fs::write(sub.join(format!("{stem}.json")), b"{not json").unwrap();
        let e = format!("{:#}", measure_dataset(d.path()).unwrap_err());
        assert!(
            e.contains(&format!("{stem}.json")) && e.contains("not valid metadata"),
            "{e}"
        );
        std::fs::write(
            sub.join(format!("{stem}.json")),
            br#"{"objects": [], "ground_material": "x"}"#,
        )
        .unwrap();
        // A PNG header claiming 100000 x 100000 pixels: refused before any allocation.
        let mut huge = b"\x89PNG\r\n\x1a\n\0\0\0\x0dIHDR".to_vec();
        huge.extend(100_000u32.to_be_bytes());
        huge.extend(100_000u32.to_be_bytes());
        huge.extend([8, 3, 0, 0, 0, 0, 0, 0, 0]);
        std::fs::write(sub.join(format!("{stem}_flat.png")), &huge).unwrap();
        let e = format!("{:#}", measure_dataset(d.path()).unwrap_err());
        assert!(
            e.contains("_flat.png") && e.contains("100000x100000"),
            "{e}"
        );
        std::fs::write(sub.join(format!("{stem}_flat.png")), b"garbage").unwrap();
        let e = format!("{:#}", measure_dataset(d.path()).unwrap_err());
        assert!(e.contains("_flat.png") && e.contains("not a PNG"), "{e}");
        let e = format!("{:#}", measure_dataset(&d.path().join("nope")).unwrap_err());
        assert!(e.contains("does not exist"), "{e}");
    }
}
