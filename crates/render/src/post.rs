//! Turning Blender's float passes into the final 8- and 16-bit PNG files.
//!
//! The encodings are documented in `docs/output-format.md`; the constants come from the
//! pass table (`clevrtex_scene::passes`), the single source of the numbers written into each
//! sample's metadata.

use std::path::Path;

use crate::error::{RenderError, Result};

pub use clevrtex_scene::passes::{
    PngKind, DEPTH_BACKGROUND, DEPTH_SCALE_M, NORMAL_BACKGROUND, SHADOW_EPS, SHADOW_REL_EPS,
    SHADOW_UNDEFINED,
};

/// Per-object visibility measured on a mask.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, serde::Serialize)]
pub struct ObjectPixels {
    /// Visible pixels.
    pub pixels: u64,
    /// 2D bounding box `[x_min, y_min, x_max, y_max]`, inclusive pixel coordinates, y down;
    /// `None` when the object is not visible at all.
    pub bbox: Option<[u32; 4]>,
}

/// Exact instance ids from Blender's object-index pass: 0 = backdrop, `i` = object `i - 1`
/// of the scene. Fails if a value is not an integer in `0..=n_objects`: the pass must
/// never be filtered or colour-managed.
pub fn instance_ids(index_ob: &[f32], n_objects: usize, source: &Path) -> Result<Vec<u8>> {
    if n_objects > 255 {
        return Err(RenderError::BadOutput {
            path: source.to_path_buf(),
            problem: format!("{n_objects} objects do not fit an 8-bit mask"),
        });
    }
    let mut ids = Vec::with_capacity(index_ob.len());
    for (i, &v) in index_ob.iter().enumerate() {
        let r = v.round();
        if !(v - r).abs().lt(&1e-3) || r < 0.0 || r > n_objects as f32 {
            return Err(RenderError::BadOutput {
                path: source.to_path_buf(),
                problem: format!(
                    "object index {v} at pixel {i} is not an instance id in 0..={n_objects}"
                ),
            });
        }
        ids.push(r as u8);
    }
    Ok(ids)
}

/// Visible pixels and bounding box of objects `1..=n_objects` in an id image.
pub fn object_pixels(ids: &[u8], width: usize, n_objects: usize) -> Vec<ObjectPixels> {
    let mut out = vec![ObjectPixels::default(); n_objects];
    for (i, &id) in ids.iter().enumerate() {
        if id == 0 || id as usize > n_objects {
            continue;
        }
        let (x, y) = ((i % width) as u32, (i / width) as u32);
        let o = &mut out[id as usize - 1];
        o.pixels += 1;
        o.bbox = Some(match o.bbox {
            None => [x, y, x, y],
            Some([x0, y0, x1, y1]) => [x0.min(x), y0.min(y), x1.max(x), y1.max(y)],
        });
    }
    out
}

/// The visibility threshold at a resolution: an object needs MORE than this many pixels
/// ([`clevrtex_scene::visibility::threshold`]).
pub fn visibility_threshold(width: u32, height: u32) -> u64 {
    clevrtex_scene::visibility::threshold(width, height)
}

/// Depth in metres (Cycles' `Depth` pass: planar distance along the camera's view axis)
/// as 16-bit values of [`DEPTH_SCALE_M`]; no hit or out of range -> [`DEPTH_BACKGROUND`].
pub fn encode_depth(z: &[f32]) -> Vec<u16> {
    z.iter()
        .map(|&d| {
            let units = d as f64 / DEPTH_SCALE_M;
            if !units.is_finite() || units <= 0.0 || units >= DEPTH_BACKGROUND as f64 - 0.5 {
                DEPTH_BACKGROUND
            } else {
                units.round() as u16
            }
        })
        .collect()
}

/// World-space normals in [-1, 1] as 16-bit `round((n + 1) / 2 * 65535)`, RGB = XYZ.
/// Background pixels have normal (0, 0, 0) and so encode as 32768 in every channel.
pub fn encode_normal(x: &[f32], y: &[f32], z: &[f32]) -> Vec<u16> {
    let enc = |v: f32| {
        let v = if v.is_finite() {
            v.clamp(-1.0, 1.0)
        } else {
            0.0
        };
        (((v as f64 + 1.0) / 2.0) * 65535.0).round() as u16
    };
    let mut out = Vec::with_capacity(x.len() * 3);
    for i in 0..x.len() {
        out.extend([enc(x[i]), enc(y[i]), enc(z[i])]);
    }
    out
}

/// Linear diffuse colour as 8-bit sRGB (the standard transfer curve, no view transform).
pub fn encode_albedo(r: &[f32], g: &[f32], b: &[f32]) -> Vec<u8> {
    let mut out = Vec::with_capacity(r.len() * 3);
    for i in 0..r.len() {
        out.extend([srgb8(r[i]), srgb8(g[i]), srgb8(b[i])]);
    }
    out
}

fn srgb8(v: f32) -> u8 {
    let v = if v.is_finite() {
        v.clamp(0.0, 1.0)
    } else {
        0.0
    };
    let s = if v <= 0.003_130_8 {
        12.92 * v
    } else {
        1.055 * v.powf(1.0 / 2.4) - 0.055
    };
    (s * 255.0).round() as u8
}

/// Radius in pixels of the shadow pass's filter window ([`SHADOW_FILTER`]): 0, no filter.
/// Since the shadow renders sample each pixel at its centre (16 samples at the default 64),
/// the error left is Monte-Carlo noise on shadow edges, which every window tried blurs more
/// than it denoises (3x3 windows, with or without a limit on the difference of the
/// neighbours' own values: 0.0104 -> 0.0109-0.0142 mean RMSE over five scenes; helpful only
/// at 8 samples; `docs/notes/performance.md`, "Shadow pass").
pub const SHADOW_FILTER_RADIUS: usize = 0;
/// Relative tolerance of the unshadowed light between a pixel and the neighbours it averages
/// ([`SHADOW_FILTER`]).
pub const SHADOW_FILTER_TOLERANCE: f32 = 0.25;

/// The filter of the shipped shadow pass (measured in `docs/notes/performance.md`, "Shadow pass").
pub const SHADOW_FILTER: ShadowFilter = ShadowFilter {
    radius: SHADOW_FILTER_RADIUS,
    tolerance: SHADOW_FILTER_TOLERANCE,
    range: f32::INFINITY,
    ratio_of_sums: true,
};

/// The unshadowed luminance below which the shadow ratio of an image is undefined:
/// [`SHADOW_EPS`], or [`SHADOW_REL_EPS`] of the 99th percentile of `u` over the pixels above
/// [`SHADOW_EPS`] if that is more.
pub fn shadow_undefined_below(u: &[f32]) -> f32 {
    let mut lit: Vec<f32> = u
        .iter()
        .copied()
        .filter(|v| v.is_finite() && *v >= SHADOW_EPS)
        .collect();
    if lit.is_empty() {
        return SHADOW_EPS;
    }
    let k = ((lit.len() - 1) as f64 * 0.99).round() as usize;
    let (_, p99, _) = lit.select_nth_unstable_by(k, f32::total_cmp);
    SHADOW_EPS.max(SHADOW_REL_EPS * *p99)
}

/// An edge-aware box filter of the shadow ratio: a pixel averages the neighbours within
/// `radius` (a `(2r+1)^2` window) that show the same instance id and whose unshadowed light
/// is within `tolerance` (relative) of its own, i.e. the same surface, lit alike. Penumbrae
/// are smooth, so this cuts their Monte-Carlo visibility noise by ~sqrt(pixels averaged);
/// a different object or a crease (another normal sees the lights differently) is never
/// mixed in, and where every neighbour is unshadowed (`lit == un`) the result stays exactly 0.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ShadowFilter {
    /// Window radius in pixels; 0 = no filtering.
    pub radius: usize,
    /// Largest relative difference `|u_j - u_i| / u_i` of unshadowed light admitted.
    pub tolerance: f32,
    /// Largest difference of a neighbour's own unfiltered shadow `1 - l_j / u_j` from the
    /// pixel's (keeps shadow edges out of the average); infinity: no limit.
    pub range: f32,
    /// `1 - sum(lit) / sum(un)` over the neighbours (true) or the mean of their
    /// `1 - lit / un` (false).
    pub ratio_of_sums: bool,
}

/// Shadow amount `1 - L_shadowed / L_unshadowed` of direct light (luminances `lit` and
/// `unshadowed`; the bridge renders both at once on white diffuse surfaces), filtered by
/// `filter` within each instance of `ids` (row-major, `width` wide), clamped to [0, 1], as
/// 8-bit (255 = fully shadowed). Where the unshadowed light is below
/// [`shadow_undefined_below`] the ratio is undefined and the value is [`SHADOW_UNDEFINED`].
pub fn encode_shadow(
    lit: &[f32],
    unshadowed: &[f32],
    ids: &[u8],
    width: usize,
    filter: ShadowFilter,
) -> Vec<u8> {
    filter_shadow(lit, unshadowed, ids, width, filter)
        .into_iter()
        .map(|s| match s {
            None => SHADOW_UNDEFINED,
            Some(v) => (v.clamp(0.0, 1.0) * 255.0).round() as u8,
        })
        .collect()
}

/// The filtered shadow `1 - l / u` per pixel (see [`ShadowFilter`]) of the luminances `l`
/// (with object shadows) and `u` (without), unclamped; `None` where the ratio is undefined
/// (`u` below [`shadow_undefined_below`] or not finite).
pub fn filter_shadow(
    l: &[f32],
    u: &[f32],
    ids: &[u8],
    width: usize,
    filter: ShadowFilter,
) -> Vec<Option<f32>> {
    let eps = shadow_undefined_below(u);
    let valid = |i: usize| u[i].is_finite() && l[i].is_finite() && u[i] >= eps;
    let height = l.len().checked_div(width).unwrap_or(0);
    let r = filter.radius;
    (0..l.len())
        .map(|i| {
            if !valid(i) {
                return None;
            }
            let (x, y) = (i % width, i / width);
            let (mut sl, mut su, mut sr, mut n) = (0.0f64, 0.0f64, 0.0f64, 0u32);
            for yy in y.saturating_sub(r)..=(y + r).min(height - 1) {
                for xx in x.saturating_sub(r)..=(x + r).min(width - 1) {
                    let j = yy * width + xx;
                    if ids[j] != ids[i]
                        || !valid(j)
                        || (u[j] - u[i]).abs() > filter.tolerance * u[i]
                        || (l[i] / u[i] - l[j] / u[j]).abs() > filter.range
                    {
                        continue;
                    }
                    sl += f64::from(l[j]);
                    su += f64::from(u[j]);
                    sr += f64::from(1.0 - l[j] / u[j]);
                    n += 1;
                }
            }
            Some(match filter.ratio_of_sums {
                true => (1.0 - sl / su) as f32,
                false => (sr / f64::from(n)) as f32,
            })
        })
        .collect()
}

/// The distinct colour of instance id `i` in the mask's palette (0 = black): golden-angle hues
/// with alternating brightness, so neighbouring ids look different.
pub fn id_colour(i: u8) -> [u8; 3] {
    if i == 0 {
        return [0, 0, 0];
    }
    let h = (f64::from(i) * 0.618_033_988_75).fract() * 6.0;
    let v = if i.is_multiple_of(2) { 0.75 } else { 1.0 };
    let c = v * 0.85;
    let x = c * (1.0 - ((h % 2.0) - 1.0).abs());
    let (r, g, b) = match h as u32 {
        0 => (c, x, 0.0),
        1 => (x, c, 0.0),
        2 => (0.0, c, x),
        3 => (0.0, x, c),
        4 => (x, 0.0, c),
        _ => (c, 0.0, x),
    };
    let m = v - c;
    let q = |t: f64| ((t + m) * 255.0).round() as u8;
    [q(r), q(g), q(b)]
}

/// The mask PNG's palette: [`id_colour`] of every id.
fn palette() -> Vec<u8> {
    (0..=255u8).flat_map(id_colour).collect()
}

/// Encode a PNG into memory. `data8` is used for 8-bit kinds, `data16` for 16-bit ones.
pub fn encode_png(
    kind: PngKind,
    width: u32,
    height: u32,
    data8: &[u8],
    data16: &[u16],
) -> Result<Vec<u8>, png::EncodingError> {
    let mut bytes = Vec::new();
    {
        let mut enc = png::Encoder::new(&mut bytes, width, height);
        let (color, depth) = match kind {
            PngKind::Palette8 => (png::ColorType::Indexed, png::BitDepth::Eight),
            PngKind::Gray8 => (png::ColorType::Grayscale, png::BitDepth::Eight),
            PngKind::Rgb8 => (png::ColorType::Rgb, png::BitDepth::Eight),
            PngKind::Gray16 => (png::ColorType::Grayscale, png::BitDepth::Sixteen),
            PngKind::Rgb16 => (png::ColorType::Rgb, png::BitDepth::Sixteen),
        };
        enc.set_color(color);
        enc.set_depth(depth);
        if let PngKind::Palette8 = kind {
            enc.set_palette(palette());
        }
        let mut w = enc.write_header()?;
        match depth {
            png::BitDepth::Sixteen => {
                let be: Vec<u8> = data16.iter().flat_map(|v| v.to_be_bytes()).collect();
                w.write_image_data(&be)?;
            }
            _ => w.write_image_data(data8)?,
        }
        w.finish()?;
    }
    Ok(bytes)
}

/// A PNG without its text chunks (`tEXt`, `zTXt`, `iTXt`) and time stamp (`tIME`): Blender
/// writes the render's timings there (`cycles.ViewLayer.render_time`...), which would make
/// two renders of the same pixels differ in bytes. Every other chunk is kept as it is (same
/// bytes, same CRCs). `path` names the file in errors.
pub fn strip_png_text(bytes: &[u8], path: &Path) -> Result<Vec<u8>> {
    const SIGNATURE: &[u8] = b"\x89PNG\r\n\x1a\n";
    let bad = |problem: &str| RenderError::BadOutput {
        path: path.to_path_buf(),
        problem: problem.to_string(),
    };
    if !bytes.starts_with(SIGNATURE) {
        return Err(bad("not a PNG (bad signature)"));
    }
    let mut out = SIGNATURE.to_vec();
    let mut pos = SIGNATURE.len();
    while pos < bytes.len() {
        let len = bytes
            .get(pos..pos + 4)
            .map(|b| u32::from_be_bytes([b[0], b[1], b[2], b[3]]) as usize)
            .ok_or_else(|| bad("truncated PNG chunk"))?;
        let end = pos
            .checked_add(12 + len)
            .filter(|&e| e <= bytes.len())
            .ok_or_else(|| bad("truncated PNG chunk"))?;
        let kind = &bytes[pos + 4..pos + 8];
        if !matches!(kind, b"tEXt" | b"zTXt" | b"iTXt" | b"tIME") {
            out.extend_from_slice(&bytes[pos..end]);
        }
        if kind == b"IEND" {
            break;
        }
        pos = end;
    }
    Ok(out)
}

/// Write bytes as `path` through the one atomic writer ([`clevrtex_dataset::atomic::write`]:
/// a unique temporary, created exclusively without following a link, synced, renamed; no
/// temporary left on error, a full disk included).
pub fn write_file(path: &Path, bytes: &[u8]) -> Result<()> {
    clevrtex_dataset::atomic::write(path, bytes).map_err(|e| RenderError::write(path, e))
}

pub use clevrtex_dataset::png::DecodedPng;

/// Read a PNG written by this crate or by Blender, without any conversion (palette indices
/// stay indices, 16-bit stays 16-bit), for checks and tests.
pub fn decode_png(path: &Path) -> Result<DecodedPng> {
    let bytes = std::fs::read(path).map_err(|e| {
        RenderError::io(
            "cannot read",
            path,
            e,
            "check that the file exists and is readable",
        )
    })?;
    decode_png_bytes(&bytes, path)
}

/// [`decode_png`] of bytes already read ([`clevrtex_dataset::png::decode`]); `path` names them
/// in errors.
pub fn decode_png_bytes(bytes: &[u8], path: &Path) -> Result<DecodedPng> {
    clevrtex_dataset::png::decode(bytes).map_err(|problem| RenderError::BadOutput {
        path: path.to_path_buf(),
        problem,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn text_chunks_are_stripped_and_pixels_kept() {
        let png = encode_png(PngKind::Rgb8, 2, 1, &[1, 2, 3, 4, 5, 6], &[]).unwrap();
        // Insert a tEXt chunk after IHDR (8 + 25 bytes), as Blender writes its timings.
        let mut with_text = png[..33].to_vec();
        let body = b"cycles.ViewLayer.render_time\x0000:00.05";
        with_text.extend((body.len() as u32).to_be_bytes());
        with_text.extend(b"tEXt");
        with_text.extend(body);
        with_text.extend([0, 0, 0, 0]); // CRC is not checked by the stripper
        with_text.extend(&png[33..]);
        let p = Path::new("x.png");
        assert_eq!(strip_png_text(&with_text, p).unwrap(), png);
        assert_eq!(strip_png_text(&png, p).unwrap(), png);
        assert!(strip_png_text(&png[..40], p).is_err());
    }

    #[test]
    fn ids_must_be_exact() {
        let p = Path::new("x.exr");
        assert_eq!(instance_ids(&[0.0, 1.0, 2.0], 2, p).unwrap(), vec![0, 1, 2]);
        assert!(instance_ids(&[0.5], 2, p).is_err());
        assert!(instance_ids(&[3.0], 2, p).is_err());
        assert!(instance_ids(&[f32::NAN], 2, p).is_err());
    }

    #[test]
    fn counts_and_boxes() {
        let ids = [0, 1, 1, 0, 2, 0];
        let o = object_pixels(&ids, 3, 3);
        assert_eq!(
            o[0],
            ObjectPixels {
                pixels: 2,
                bbox: Some([1, 0, 2, 0])
            }
        );
        assert_eq!(
            o[1],
            ObjectPixels {
                pixels: 1,
                bbox: Some([1, 1, 1, 1])
            }
        );
        assert_eq!(
            o[2],
            ObjectPixels {
                pixels: 0,
                bbox: None
            }
        );
    }

    #[test]
    fn threshold_scales_with_resolution() {
        assert_eq!(visibility_threshold(320, 240), 200);
        assert_eq!(visibility_threshold(640, 480), 800);
        assert_eq!(visibility_threshold(64, 48), 8);
    }

    #[test]
    fn depth_encoding() {
        assert_eq!(
            encode_depth(&[1.2345, 1e10, f32::NAN, -1.0, 70.0]),
            vec![1235, 65535, 65535, 65535, 65535]
        );
    }

    #[test]
    fn shadow_is_never_nan() {
        let z = [0.0f32, 1.0, 0.5];
        let u = [0.0f32, 1.0, 1.0];
        let s = encode_shadow(&z, &u, &[0; 3], 3, WINDOW_3X3);
        // Pixels 1 and 2 are lit alike (u = 1) on one surface: filtered together.
        assert_eq!(s, vec![SHADOW_UNDEFINED, 64, 64]);
        let s = encode_shadow(&z, &u, &[0; 3], 3, SHADOW_FILTER);
        assert_eq!(s, vec![SHADOW_UNDEFINED, 0, 128]);
    }

    #[test]
    fn shadow_is_undefined_under_a_hundredth_of_the_typical_light() {
        // 200 pixels lit at 1.0, one at 0.005 and one at 0.02 (both above SHADOW_EPS).
        let mut u = vec![1.0f32; 202];
        u[200] = 0.005;
        u[201] = 0.02;
        let l: Vec<f32> = u.iter().map(|v| v / 2.0).collect();
        assert!((shadow_undefined_below(&u) - 0.01).abs() < 1e-7);
        let s = encode_shadow(&l, &u, &[0; 202], 202, SHADOW_FILTER);
        assert_eq!(s[200], SHADOW_UNDEFINED);
        assert_eq!(s[201], 128);
        assert_eq!(s[0], 128);
        // A dark image keeps the absolute floor.
        assert_eq!(shadow_undefined_below(&[0.0, 0.001, 0.002]), SHADOW_EPS);
        assert_eq!(shadow_undefined_below(&[0.0, f32::NAN]), SHADOW_EPS);
    }

    /// A 3x3 window (the shipped pass has none; the filter stays measurable).
    const WINDOW_3X3: ShadowFilter = ShadowFilter {
        radius: 1,
        tolerance: 0.25,
        range: f32::INFINITY,
        ratio_of_sums: true,
    };

    /// A deterministic noisy smooth ramp `w x h`: the true shadow, and `(lit, un)` with
    /// visibility noise of +-0.1 on `lit`.
    fn noisy_ramp(w: usize, h: usize) -> (Vec<f32>, Vec<f32>, Vec<f32>) {
        let mut state = 12345u32;
        let mut next = || {
            state = state.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
            (state >> 8) as f32 / (1u32 << 24) as f32 - 0.5
        };
        let truth: Vec<f32> = (0..w * h)
            .map(|i| (i % w) as f32 / w as f32 * 0.8)
            .collect();
        let un = vec![2.0f32; w * h];
        let lit = truth
            .iter()
            .map(|t| (2.0 * (1.0 - t) + 0.4 * next()).max(0.0))
            .collect();
        (truth, lit, un)
    }

    fn rmse(a: &[Option<f32>], truth: &[f32]) -> f32 {
        let se: f32 = a
            .iter()
            .zip(truth)
            .map(|(a, t)| (a.unwrap() - t).powi(2))
            .sum();
        (se / truth.len() as f32).sqrt()
    }

    #[test]
    fn shadow_filter_reduces_the_noise_of_a_smooth_ramp() {
        let (w, h) = (64, 48);
        let (truth, lit, un) = noisy_ramp(w, h);
        let ids = vec![1u8; w * h];
        let raw = filter_shadow(
            &lit,
            &un,
            &ids,
            w,
            ShadowFilter {
                radius: 0,
                ..WINDOW_3X3
            },
        );
        for ratio_of_sums in [true, false] {
            let f = ShadowFilter {
                ratio_of_sums,
                ..WINDOW_3X3
            };
            let filtered = filter_shadow(&lit, &un, &ids, w, f);
            let (e0, e1) = (rmse(&raw, &truth), rmse(&filtered, &truth));
            assert!(e1 < e0 / 2.0, "{ratio_of_sums}: RMSE {e0} -> {e1}");
        }
    }

    #[test]
    fn shadow_filter_never_mixes_instances_nor_unlike_light_and_keeps_zeros() {
        // Left half id 1 fully shadowed, right half id 2 unshadowed: no bleeding either way.
        let (w, h) = (10, 6);
        let ids: Vec<u8> = (0..w * h).map(|i| if i % w < 5 { 1 } else { 2 }).collect();
        let un = vec![1.0f32; w * h];
        let lit: Vec<f32> = ids
            .iter()
            .map(|&id| if id == 1 { 0.0 } else { 1.0 })
            .collect();
        let s = filter_shadow(&lit, &un, &ids, w, WINDOW_3X3);
        for (i, v) in s.iter().enumerate() {
            assert_eq!(v.unwrap(), if ids[i] == 1 { 1.0 } else { 0.0 }, "pixel {i}");
        }
        // One id, but the right half lit 3x brighter (another face): not mixed either.
        let ids = vec![1u8; w * h];
        let un: Vec<f32> = (0..w * h)
            .map(|i| if i % w < 5 { 1.0 } else { 3.0 })
            .collect();
        let s = filter_shadow(&lit, &un, &ids, w, WINDOW_3X3);
        for (i, v) in s.iter().enumerate() {
            let want = if i % w < 5 { 1.0 } else { 1.0 - 1.0 / 3.0 };
            assert!((v.unwrap() - want).abs() < 1e-6, "pixel {i}: {v:?}");
        }
        // A noisy, unshadowed surface (lit == un in every pixel) stays exactly 0.
        let (_, noisy, _) = noisy_ramp(w, h);
        let s = encode_shadow(&noisy, &noisy, &ids, w, WINDOW_3X3);
        assert!(s.iter().all(|&v| v == 0 || v == SHADOW_UNDEFINED), "{s:?}");
    }

    #[test]
    fn shadow_filter_range_keeps_a_hard_edge() {
        // One surface, one id, one light level: columns 0-4 shadowed, 5-9 not.
        let (w, h) = (10, 4);
        let ids = vec![1u8; w * h];
        let un = vec![1.0f32; w * h];
        let lit: Vec<f32> = (0..w * h)
            .map(|i| if i % w < 5 { 0.0 } else { 1.0 })
            .collect();
        let blurred = filter_shadow(&lit, &un, &ids, w, WINDOW_3X3);
        assert!((blurred[4].unwrap() - 2.0 / 3.0).abs() < 1e-6);
        let edged = ShadowFilter {
            range: 0.3,
            ..WINDOW_3X3
        };
        let kept = filter_shadow(&lit, &un, &ids, w, edged);
        for (i, v) in kept.iter().enumerate() {
            assert_eq!(v.unwrap(), if i % w < 5 { 1.0 } else { 0.0 }, "pixel {i}");
        }
    }

    #[test]
    fn palette_png_round_trips() {
        let bytes = encode_png(PngKind::Palette8, 2, 1, &[0, 3], &[]).unwrap();
        let mut dec = png::Decoder::new(std::io::Cursor::new(bytes));
        dec.set_transformations(png::Transformations::IDENTITY);
        let mut r = dec.read_info().unwrap();
        assert_eq!(r.info().color_type, png::ColorType::Indexed);
        let mut buf = vec![0; r.output_buffer_size().unwrap()];
        r.next_frame(&mut buf).unwrap();
        assert_eq!(&buf[..2], &[0, 3]);
    }
}
