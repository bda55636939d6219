//! `clevrtex._native`: the Rust half of the Python package `clevrtex` (the Python half, in
//! `python/clevrtex/`, turns numpy arrays and torch tensors into bytes and keeps the running
//! statistics). Scoring and decoding run with the GIL released, in parallel over images.

use std::path::Path;

use clevrtex_eval::dataset::discover_gt;
use clevrtex_eval::predict::argmax_masks;
use clevrtex_eval::resize::{crop_box, crop_resize_bilinear_rgb, crop_resize_nearest};
use clevrtex_eval::{read, score_image, EvalError, Metric, Split};
use pyo3::exceptions::{PyOSError, PyValueError};
use pyo3::prelude::*;
use pyo3::types::PyBytes;
use rayon::prelude::*;

fn value_error(e: impl std::fmt::Display) -> PyErr {
    PyValueError::new_err(e.to_string())
}

fn eval_error(e: EvalError) -> PyErr {
    match e {
        EvalError::Io { .. } => PyOSError::new_err(e.to_string()),
        other => value_error(other),
    }
}

fn u32s(b: &[u8]) -> Vec<u32> {
    b.chunks_exact(4)
        .map(|c| u32::from_le_bytes([c[0], c[1], c[2], c[3]]))
        .collect()
}

fn f32s(b: &[u8]) -> Vec<f32> {
    b.chunks_exact(4)
        .map(|c| f32::from_le_bytes([c[0], c[1], c[2], c[3]]))
        .collect()
}

/// [`argmax_masks`] (first index on ties, NaN the maximum) read straight from little-endian
/// f32 bytes `(k, n)`, without a copy of the masks.
fn argmax_le_bytes(m: &[u8], k: usize, n: usize) -> Vec<u32> {
    let decode = |s: usize, out: &mut [f32]| {
        for (o, c) in out
            .iter_mut()
            .zip(m[4 * s * n..4 * (s + 1) * n].chunks_exact(4))
        {
            *o = f32::from_le_bytes([c[0], c[1], c[2], c[3]]);
        }
    };
    let mut best = vec![0.0f32; n];
    decode(0, &mut best);
    let mut cur = vec![0.0f32; n];
    let mut idx = vec![0u32; n];
    for s in 1..k {
        decode(s, &mut cur);
        // Branch-free, so it vectorises: the first maximum wins, a NaN is kept once taken.
        for ((b, i), &v) in best.iter_mut().zip(idx.iter_mut()).zip(&cur) {
            let take = !b.is_nan() & (v.is_nan() | (v > *b));
            *b = if take { v } else { *b };
            *i = if take { s as u32 } else { *i };
        }
    }
    idx
}

/// One image's scores: every metric (indexed like `metric_names()`), the matched IoU and size
/// of each true slot, and each true slot's squared error when images were given.
type ImageOut = (Vec<Option<f64>>, Vec<f64>, Vec<u64>, Option<Vec<f64>>);

/// Score a batch. `truth`: `batch * pixels` little-endian u32 ids. `pred`: u32 ids
/// (`masks = 0`) or `batch * masks * pixels` f32 soft masks (argmax, first index on ties, NaN
/// the maximum; `no_background` puts `1 - sum` in front). `min_slots`: the matching's size at
/// least (the public evaluator pads both sides to `max(true slots, predicted slots)`).
/// `true_rgb` / `pred_rgb`: `batch * 3 * pixels` f32 (planar, as torch holds them) for MSE.
#[pyfunction]
#[pyo3(signature = (truth, pred, batch, pixels, masks, no_background, min_slots, true_rgb=None, pred_rgb=None))]
#[allow(clippy::too_many_arguments)]
fn score(
    py: Python<'_>,
    truth: &[u8],
    pred: &[u8],
    batch: usize,
    pixels: usize,
    masks: usize,
    no_background: bool,
    min_slots: usize,
    true_rgb: Option<&[u8]>,
    pred_rgb: Option<&[u8]>,
) -> PyResult<Vec<ImageOut>> {
    let n = batch * pixels;
    let per = if masks == 0 { 1 } else { masks };
    if truth.len() != 4 * n || pred.len() != 4 * n * per {
        return Err(value_error(format!(
            "internal: buffer sizes {} and {} do not fit {batch} images of {pixels} pixels",
            truth.len(),
            pred.len()
        )));
    }
    let rgb_ok = |b: Option<&[u8]>| b.is_none_or(|b| b.len() == 12 * n);
    if !rgb_ok(true_rgb) || !rgb_ok(pred_rgb) {
        return Err(value_error("internal: image buffers do not fit the masks"));
    }
    let out = py.allow_threads(|| {
        (0..batch)
            .into_par_iter()
            .map(|b| {
                let t = u32s(&truth[4 * b * pixels..4 * (b + 1) * pixels]);
                let (p, slots) = if masks == 0 {
                    let p = u32s(&pred[4 * b * pixels..4 * (b + 1) * pixels]);
                    let slots = p.iter().max().map_or(1, |&m| m as usize + 1);
                    (p, slots)
                } else {
                    let m = &pred[4 * b * per * pixels..4 * (b + 1) * per * pixels];
                    let labels = if no_background {
                        argmax_masks(&f32s(m), masks, pixels, true)
                    } else {
                        argmax_le_bytes(m, masks, pixels)
                    };
                    (labels, masks + usize::from(no_background))
                };
                let mut s = score_image(&t, &p, slots.max(min_slots), None);
                let mut sq = None;
                if let (Some(tr), Some(pr)) = (true_rgb, pred_rgb) {
                    let range = 12 * b * pixels..12 * (b + 1) * pixels;
                    let (tr, pr) = (f32s(&tr[range.clone()]), f32s(&pr[range]));
                    // Difference and square in f32, sums in f64 (docs/eval.md).
                    let mut per_true = vec![0.0f64; s.true_sizes.len()];
                    let mut total = 0.0f64;
                    for (i, &label) in t.iter().enumerate() {
                        let mut e = 0.0f64;
                        for c in 0..3 {
                            let d = pr[c * pixels + i] - tr[c * pixels + i];
                            e += (d * d) as f64;
                        }
                        per_true[label as usize] += e;
                        total += e;
                    }
                    s.values[Metric::Mse.index()] = total.is_finite().then_some(total);
                    sq = Some(per_true);
                }
                (s.values.to_vec(), s.iou_per_true, s.true_sizes, sq)
            })
            .collect::<Vec<_>>()
    });
    Ok(out)
}

/// The names of every metric, in the order `score` returns them.
#[pyfunction]
fn metric_names() -> Vec<&'static str> {
    Metric::ALL.iter().map(|m| m.name()).collect()
}

/// The default metrics of a protocol.
#[pyfunction]
fn protocol_metrics(protocol: &str) -> PyResult<Vec<&'static str>> {
    let p = clevrtex_eval::Protocol::from_name(protocol).ok_or_else(|| {
        value_error(format!(
            "unknown protocol `{protocol}`; known: clevrtex, native, deepmind, ocl"
        ))
    })?;
    Ok(p.default_metrics().iter().map(|m| m.name()).collect())
}

/// The samples of a dataset in the published layout: `(variant, [(index, image, mask, meta)])`
/// for one split (`test`, `val`, `train`, `all`; test-only variants have `test` = all).
#[pyfunction]
#[pyo3(signature = (path, variant=None, split="test"))]
#[allow(clippy::type_complexity)]
fn discover(
    py: Python<'_>,
    path: &str,
    variant: Option<&str>,
    split: &str,
) -> PyResult<(String, Vec<(u64, String, String, String)>)> {
    let split = match split {
        "test" => Split::Test,
        "val" => Split::Val,
        "train" => Split::Train,
        "all" => Split::All,
        other => {
            return Err(value_error(format!(
                "unknown split `{other}`; known: test, val, train, all"
            )))
        }
    };
    py.allow_threads(|| {
        let (variant, samples) = discover_gt(Path::new(path), variant).map_err(eval_error)?;
        // As the public loader: a test-only variant is read whole, whatever the split.
        let split = if is_test_only(&variant) {
            Split::All
        } else {
            split
        };
        let range = split.range(samples.len(), &variant).map_err(eval_error)?;
        let s = |p: &Path| p.display().to_string();
        let list = samples[range]
            .iter()
            .map(|x| (x.index, s(&x.image), s(&x.mask), s(&x.meta)))
            .collect();
        Ok((variant, list))
    })
}

/// A variant with only a test split (its config says `"splits": "test_only"`, e.g. `outd`).
fn is_test_only(variant: &str) -> bool {
    clevrtex_eval::Split::Val.range(10, variant).is_err()
}

/// Read one sample as the public `CLEVRTEX` loader does: `(rgb, labels, height, width)` with
/// `rgb` 8-bit interleaved and `labels` little-endian u32; with `crop`, the centre square of
/// side `int(0.8 min(W, H))`; resized to `side` (Pillow-exact bilinear for the image, nearest
/// for the mask), or kept at the crop's size when `side` is `None`.
#[pyfunction]
#[pyo3(signature = (image, mask, crop=true, side=Some(128)))]
fn load_sample<'py>(
    py: Python<'py>,
    image: &str,
    mask: &str,
    crop: bool,
    side: Option<usize>,
) -> PyResult<(Bound<'py, PyBytes>, Bound<'py, PyBytes>, usize, usize)> {
    let (rgb, labels, h, w) = py.allow_threads(|| -> PyResult<_> {
        let read_file = |p: &str| {
            std::fs::read(p).map_err(|e| PyOSError::new_err(format!("cannot read `{p}`: {e}")))
        };
        let img = read::png_rgb(&read_file(image)?)
            .map_err(|r| value_error(format!("cannot decode `{image}`: {r}")))?;
        let msk = read::png_labels(&read_file(mask)?)
            .map_err(|r| value_error(format!("cannot decode `{mask}`: {r}")))?;
        let (w, h) = (img.width, img.height);
        if (msk.width, msk.height) != (w, h) {
            return Err(value_error(format!(
                "`{image}` is {w}x{h} but its mask is {}x{}",
                msk.width, msk.height
            )));
        }
        match (crop, side) {
            (false, None) => Ok((img.rgb, msk.labels, h, w)),
            (true, side) => {
                let side = side.unwrap_or_else(|| crop_box(w, h).2);
                let rgb = crop_resize_bilinear_rgb(&img.rgb, w, h, side);
                let labels = crop_resize_nearest(&msk.labels, w, h, side);
                match (rgb, labels) {
                    (Some(r), Some(l)) => Ok((r, l, side, side)),
                    _ => Err(value_error(format!("`{image}` is too small to crop"))),
                }
            }
            (false, Some(_)) => Err(value_error(
                "resizing without the crop is not supported: pass crop=True or resize=None",
            )),
        }
    })?;
    let lb: Vec<u8> = labels.iter().flat_map(|v| v.to_le_bytes()).collect();
    Ok((PyBytes::new(py, &rgb), PyBytes::new(py, &lb), h, w))
}

/// The extension module.
#[pymodule]
fn _native(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_function(wrap_pyfunction!(score, m)?)?;
    m.add_function(wrap_pyfunction!(metric_names, m)?)?;
    m.add_function(wrap_pyfunction!(protocol_metrics, m)?)?;
    m.add_function(wrap_pyfunction!(discover, m)?)?;
    m.add_function(wrap_pyfunction!(load_sample, m)?)?;
    Ok(())
}
