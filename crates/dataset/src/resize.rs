//! The benchmark's crop-and-resize protocol: a centred square crop of side
//! `int(0.8 * min(W, H))`, then nearest resize for masks and Pillow's 8-bit `BILINEAR` resize
//! (bit for bit) for images. Used by `eval` (the ground truth), the Python `Dataset` (items
//! as the public loader gives them) and `export --crop-resize` (shards as the loader's items).

/// Side of the evaluation images under the `clevrtex` protocol.
pub const EVAL_SIDE: usize = 128;

/// The crop box `(x0, y0, side)` for an image of `width x height`, as the public loader
/// computes it: side `int(0.8 * min(W, H))`, box `((W - c) // 2, (H - c) // 2, ...)`.
pub fn crop_box(width: usize, height: usize) -> (usize, usize, usize) {
    let c = (0.8 * width.min(height) as f64) as usize;
    ((width - c) / 2, (height - c) / 2, c)
}

/// Nearest-neighbour crop and resize of a label mask to `out x out`:
/// `out[y][x] = crop[floor((y + 0.5) * c / out)][floor((x + 0.5) * c / out)]`, in exact
/// integer arithmetic.
pub fn crop_resize_nearest(
    labels: &[u32],
    width: usize,
    height: usize,
    out: usize,
) -> Option<Vec<u32>> {
    if labels.len() != width * height || out == 0 {
        return None;
    }
    let (x0, y0, c) = crop_box(width, height);
    if c == 0 {
        return None;
    }
    let src = |o: usize| x_src(o, c, out);
    let cols: Vec<usize> = (0..out).map(|x| x0 + src(x)).collect();
    let mut res = Vec::with_capacity(out * out);
    for y in 0..out {
        let row = &labels[(y0 + src(y)) * width..][..width];
        res.extend(cols.iter().map(|&x| row[x]));
    }
    Some(res)
}

fn x_src(o: usize, c: usize, out: usize) -> usize {
    ((2 * o + 1) * c / (2 * out)).min(c - 1)
}

/// Fixed-point precision of Pillow's 8-bit resampling.
const PRECISION_BITS: u32 = 32 - 8 - 2;

/// Pillow's per-output-pixel taps for resizing `in_size` samples to `out_size` with the
/// bilinear (triangle) filter: `(first input index, fixed-point weights)`.
fn bilinear_coeffs(in_size: usize, out_size: usize) -> Vec<(usize, Vec<i32>)> {
    let scale = in_size as f64 / out_size as f64;
    let filterscale = scale.max(1.0);
    let support = filterscale; // bilinear support is 1.0
    let ss = 1.0 / filterscale;
    (0..out_size)
        .map(|xx| {
            let center = (xx as f64 + 0.5) * scale;
            let xmin = ((center - support + 0.5) as i64).max(0) as usize;
            let xmax = ((center + support + 0.5) as i64).min(in_size as i64).max(0) as usize;
            let taps = xmax.saturating_sub(xmin);
            let mut w: Vec<f64> = (0..taps)
                .map(|x| {
                    let d = ((x + xmin) as f64 - center + 0.5) * ss;
                    let d = d.abs();
                    if d < 1.0 {
                        1.0 - d
                    } else {
                        0.0
                    }
                })
                .collect();
            let total: f64 = w.iter().sum();
            if total != 0.0 {
                w.iter_mut().for_each(|x| *x /= total);
            }
            let fixed = w
                .iter()
                .map(|&x| {
                    let v = x * (1u32 << PRECISION_BITS) as f64;
                    if v < 0.0 {
                        (v - 0.5) as i32
                    } else {
                        (v + 0.5) as i32
                    }
                })
                .collect();
            (xmin, fixed)
        })
        .collect()
}

fn clip8(v: i32) -> u8 {
    (v >> PRECISION_BITS).clamp(0, 255) as u8
}

/// Crop an interleaved 8-bit RGB image with [`crop_box`] and resize it to `out x out` exactly
/// as Pillow's `Image.resize((out, out), BILINEAR)` does on the cropped RGB image.
///
/// Accumulators are `i32` as in Pillow: the weights of a tap sum to `2^22`, so a sum is at most
/// `255 * 2^22 + 2^21 < 2^31`.
pub fn crop_resize_bilinear_rgb(
    rgb: &[u8],
    width: usize,
    height: usize,
    out: usize,
) -> Option<Vec<u8>> {
    if rgb.len() != width * height * 3 || out == 0 {
        return None;
    }
    let (x0, y0, c) = crop_box(width, height);
    if c == 0 {
        return None;
    }
    let coeffs = bilinear_coeffs(c, out);
    let half = 1i32 << (PRECISION_BITS - 1);
    // Horizontal pass over the crop's rows: c rows x out columns.
    let mut tmp = vec![0u8; c * out * 3];
    for (y, trow) in tmp.chunks_exact_mut(out * 3).enumerate() {
        let row = &rgb[((y0 + y) * width + x0) * 3..][..c * 3];
        for ((xmin, k), px_out) in coeffs.iter().zip(trow.chunks_exact_mut(3)) {
            let src = &row[xmin * 3..][..k.len() * 3];
            let (mut r, mut g, mut b) = (half, half, half);
            for (&w, px) in k.iter().zip(src.chunks_exact(3)) {
                r += px[0] as i32 * w;
                g += px[1] as i32 * w;
                b += px[2] as i32 * w;
            }
            px_out[0] = clip8(r);
            px_out[1] = clip8(g);
            px_out[2] = clip8(b);
        }
    }
    // Vertical pass, a whole row at a time so the inner loop vectorises.
    let width3 = out * 3;
    let mut res = vec![0u8; out * width3];
    let mut acc = vec![0i32; width3];
    for ((ymin, k), orow) in coeffs.iter().zip(res.chunks_exact_mut(width3)) {
        acc.iter_mut().for_each(|a| *a = half);
        for (i, &w) in k.iter().enumerate() {
            let src = &tmp[(ymin + i) * width3..][..width3];
            for (a, &v) in acc.iter_mut().zip(src) {
                *a += v as i32 * w;
            }
        }
        for (o, &a) in orow.iter_mut().zip(&acc) {
            *o = clip8(a);
        }
    }
    Some(res)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn crop_box_of_published_size() {
        assert_eq!(crop_box(320, 240), (64, 24, 192));
    }

    #[test]
    fn identity_when_sizes_agree() {
        // 160 * 0.8 = 128: the crop is 128 and the resize is the identity.
        let rgb: Vec<u8> = (0..160 * 160 * 3).map(|i| (i * 7 % 256) as u8).collect();
        let out = crop_resize_bilinear_rgb(&rgb, 160, 160, 128).unwrap();
        let (x0, y0, _) = crop_box(160, 160);
        assert_eq!(out[0..3], rgb[(y0 * 160 + x0) * 3..][..3]);
    }
}
