//! Loading one prediction: hard labels or soft masks (argmax), and the optional
//! reconstruction, checked against the expected shape (never reshaped).

use std::path::Path;

use crate::dataset::PredFiles;
use crate::error::{corrupt, EvalError, MAX_SLOTS};
use crate::read::{self, NpyArray, NpyData};

/// A prediction ready for scoring.
#[derive(Clone, Debug, PartialEq)]
pub struct Prediction {
    /// Segment id per pixel, row-major.
    pub labels: Vec<u32>,
    /// Number of predicted slots (masks, or the largest id + 1).
    pub slots: usize,
    /// Reconstruction, when given.
    pub recon: Option<ReconImage>,
}

/// A predicted reconstruction, interleaved RGB.
#[derive(Clone, Debug, PartialEq)]
pub enum ReconImage {
    /// Floats in [0, 1] (from `.npz`).
    Unit(Vec<f32>),
    /// 8-bit values (from `_recon.png`), scored as `v / 255`.
    Bytes(Vec<u8>),
}

impl ReconImage {
    /// Borrow for [`crate::metrics::Recon`].
    pub fn as_pred(&self) -> crate::metrics::PredRgb<'_> {
        match self {
            ReconImage::Unit(v) => crate::metrics::PredRgb::Unit(v),
            ReconImage::Bytes(v) => crate::metrics::PredRgb::Bytes(v),
        }
    }
}

/// Bytes of the files read, for the provenance hash.
pub type ReadBytes = Vec<Vec<u8>>;

use crate::dataset::read_file;

fn shape_str(dims: &[usize]) -> String {
    format!(
        "({})",
        dims.iter()
            .map(|d| d.to_string())
            .collect::<Vec<_>>()
            .join(", ")
    )
}

/// What a `.npy` prediction must be: the dtypes and shapes read, not only the writer.
const NPY_HINT: &str = "save segment ids (H, W) of an integer or bool dtype, or soft masks (K, H, W) of float16/32/64, with `numpy.save` (no object dtype; integers below 2^63)";
/// What a `.npz` prediction must hold.
const NPZ_HINT: &str = "save `labels` (H, W) integer ids or `masks` (K, H, W) floats, and optionally `recon` floats in [0, 1] (3, H, W) or (H, W, 3), with `numpy.savez` or `numpy.savez_compressed` (no object dtype)";

const SHAPE_HINT: &str = "predictions must have the ground truth's evaluation shape: 128x128 (crop then resize; every protocol but `native`), the dataset's own size under `--protocol native` or `--native-size`; they are never reshaped";

fn mismatch(path: &Path, pred: &[usize], truth: &[usize]) -> EvalError {
    EvalError::ShapeMismatch {
        path: path.to_path_buf(),
        pred: shape_str(pred),
        truth: shape_str(truth),
        hint: SHAPE_HINT.into(),
    }
}

fn labels_from_ids<I: Iterator<Item = i64>>(
    path: &Path,
    ids: I,
    n: usize,
) -> Result<(Vec<u32>, usize), EvalError> {
    let mut labels = Vec::with_capacity(n);
    let mut max = 0u32;
    for v in ids {
        if v < 0 || v >= MAX_SLOTS as i64 {
            return Err(corrupt(
                path,
                format!("segment id `{v}` is outside 0..{MAX_SLOTS}"),
                "segment ids must be slot indices 0..K-1 (background 0 when there is one); relabel them compactly",
            ));
        }
        max = max.max(v as u32);
        labels.push(v as u32);
    }
    Ok((labels, max as usize + 1))
}

/// A float type soft masks are compared in.
pub trait MaskValue:
    Copy + PartialOrd + std::ops::Add<Output = Self> + std::ops::Sub<Output = Self>
{
    /// Zero.
    const ZERO: Self;
    /// One.
    const ONE: Self;
    /// Whether the value is NaN.
    fn nan(self) -> bool;
}

impl MaskValue for f32 {
    const ZERO: Self = 0.0;
    const ONE: Self = 1.0;
    fn nan(self) -> bool {
        self.is_nan()
    }
}

impl MaskValue for f64 {
    const ZERO: Self = 0.0;
    const ONE: Self = 1.0;
    fn nan(self) -> bool {
        self.is_nan()
    }
}

/// Argmax of `f32` soft masks `(K, n)`: first index on ties, NaN counts as the maximum; with
/// `no_background` a background slot `1 - Σ_k m_k` (summed in k order) is put in front.
pub fn argmax_masks(data: &[f32], k: usize, n: usize, no_background: bool) -> Vec<u32> {
    argmax_by(data, k, n, no_background, |v| v)
}

/// The one argmax kernel of `clevrtex eval` and the Python package: over the `k` soft masks
/// `m` (`(k, n)`), each value compared as `value(v)`; first index on ties, NaN the maximum;
/// with `no_background` a background `1 - Σ_k m_k` (summed in k order) in front. Blocked over
/// pixels and branch-free, so it vectorises and reads `m` once.
pub fn argmax_by<S: Copy, T: MaskValue>(
    m: &[S],
    k: usize,
    n: usize,
    no_background: bool,
    value: impl Fn(S) -> T,
) -> Vec<u32> {
    use crate::metrics::BLOCK;
    let mut out = vec![0u32; n];
    if k == 0 || n == 0 || m.len() < k * n {
        return out;
    }
    // Two buffers each for the running maximum and its index, swapped per mask: writing a
    // select into the other buffer keeps LLVM from turning it into a conditional store,
    // which it cannot vectorise without AVX.
    let (mut best, mut best2) = ([T::ZERO; BLOCK], [T::ZERO; BLOCK]);
    let (mut idx, mut idx2) = ([0u32; BLOCK], [0u32; BLOCK]);
    for (start, o) in (0..n).step_by(BLOCK).zip(out.chunks_mut(BLOCK)) {
        let len = o.len();
        let slot = |s: usize| &m[s * n + start..s * n + start + len];
        let (mut b, mut b2) = (&mut best[..len], &mut best2[..len]);
        let (mut i, mut i2) = (&mut idx[..len], &mut idx2[..len]);
        i.fill(0);
        let (first, offset) = if no_background {
            b.fill(T::ZERO);
            for s in 0..k {
                b.iter_mut()
                    .zip(slot(s))
                    .for_each(|(b, &v)| *b = *b + value(v));
            }
            b.iter_mut().for_each(|b| *b = T::ONE - *b);
            (0, 1)
        } else {
            b.iter_mut().zip(slot(0)).for_each(|(b, &v)| *b = value(v));
            (1, 0)
        };
        for s in first..k {
            let label = (s + offset) as u32;
            let src = b.iter().zip(i.iter()).zip(slot(s));
            for ((nb, ni), ((&ob, &oi), &v)) in b2.iter_mut().zip(i2.iter_mut()).zip(src) {
                let v = value(v);
                let take = !ob.nan() & (v.nan() | (v > ob));
                *nb = if take { v } else { ob };
                *ni = if take { label } else { oi };
            }
            std::mem::swap(&mut b, &mut b2);
            std::mem::swap(&mut i, &mut i2);
        }
        o.copy_from_slice(i);
    }
    out
}

fn segmentation_from_array(
    path: &Path,
    arr: &NpyArray,
    name: &str,
    hw: (usize, usize),
    no_background: bool,
) -> Result<(Vec<u32>, usize), EvalError> {
    let (w, h) = hw;
    let n = w * h;
    match name {
        "labels" => {
            if arr.shape != [h, w] {
                return Err(mismatch(path, &arr.shape, &[h, w]));
            }
            match &arr.data {
                NpyData::Int(v) => labels_from_ids(path, v.iter().copied(), n),
                _ => Err(corrupt(
                    path,
                    format!("`labels` has float dtype `{}`", arr.descr),
                    "`labels` must hold integer segment ids; for per-slot probabilities use `masks` (K, H, W)",
                )),
            }
        }
        _ => {
            // (K, H, W), or (K, 1, H, W) as models often emit.
            let s = &arr.shape;
            let k = match s.as_slice() {
                [k, hh, ww] if (*hh, *ww) == (h, w) => *k,
                [k, 1, hh, ww] if (*hh, *ww) == (h, w) => *k,
                _ => {
                    // K is the prediction's own: never made up from a shape that has none
                    // (a 0-d array was reported as "ground truth is (0, 24, 32)").
                    let truth = if s.len() == 4 {
                        format!("(K, 1, {h}, {w}) soft masks")
                    } else {
                        format!("(K, {h}, {w}) soft masks or ({h}, {w}) segment ids")
                    };
                    return Err(EvalError::ShapeMismatch {
                        path: path.to_path_buf(),
                        pred: shape_str(s),
                        truth,
                        hint: SHAPE_HINT.into(),
                    });
                }
            };
            let slots = k + usize::from(no_background);
            if k == 0 || slots > MAX_SLOTS {
                return Err(corrupt(
                    path,
                    format!("`masks` has {k} slots"),
                    &format!(
                        "give between 1 and {} masks ({} with --no-background, which adds one)",
                        MAX_SLOTS,
                        MAX_SLOTS - 1
                    ),
                ));
            }
            let labels = match &arr.data {
                NpyData::F32(v) => argmax_by(v, k, n, no_background, |x| x),
                NpyData::F64(v) => argmax_by(v, k, n, no_background, |x| x),
                NpyData::Int(v) => argmax_by(v, k, n, no_background, |x| x as f64),
            };
            Ok((labels, slots))
        }
    }
}

fn recon_from_array(
    path: &Path,
    arr: &NpyArray,
    hw: (usize, usize),
) -> Result<Vec<f32>, EvalError> {
    let (w, h) = hw;
    let n = w * h;
    let vals: Vec<f32> = match &arr.data {
        NpyData::F32(v) => v.clone(),
        NpyData::F64(v) => v.iter().map(|&x| x as f32).collect(),
        NpyData::Int(_) => {
            return Err(corrupt(
                path,
                format!("`recon` has integer dtype `{}`", arr.descr),
                "give `recon` as floats in [0, 1], shaped (3, H, W) or (H, W, 3)",
            ))
        }
    };
    match arr.shape.as_slice() {
        [3, hh, ww] if (*hh, *ww) == (h, w) => {
            let mut out = Vec::with_capacity(3 * n);
            for i in 0..n {
                out.extend_from_slice(&[vals[i], vals[n + i], vals[2 * n + i]]);
            }
            Ok(out)
        }
        [hh, ww, 3] if (*hh, *ww) == (h, w) => Ok(vals),
        s => Err(mismatch(path, s, &[3, h, w])),
    }
}

/// Names for a message: the first [`LISTED_NAMES`], then how many more (a hostile `.npz` may
/// hold thousands of arrays).
fn list_names(names: &[String]) -> String {
    let mut text = names
        .iter()
        .take(LISTED_NAMES)
        .map(|n| format!("`{n}`"))
        .collect::<Vec<_>>()
        .join(", ");
    if names.len() > LISTED_NAMES {
        text.push_str(&format!(", ... and {} more", names.len() - LISTED_NAMES));
    }
    text
}

/// How many array names an error lists.
const LISTED_NAMES: usize = 10;

/// Load the prediction for one sample, expecting `hw = (width, height)`. Returns the
/// prediction and the bytes of every file read (for hashing).
pub fn load(
    files: &PredFiles,
    hw: (usize, usize),
    no_background: bool,
) -> Result<(Prediction, ReadBytes), EvalError> {
    let (w, h) = hw;
    let n = w * h;
    let Some(seg) = &files.segmentation else {
        return Err(EvalError::Usage {
            message: "internal: no segmentation file".into(),
            hint: "report this bug".into(),
        });
    };
    let bytes = read_file(seg)?;
    let name = seg.file_name().and_then(|s| s.to_str()).unwrap_or("");
    let mut recon = None;
    let (labels, slots) = if name.ends_with(".png") {
        // The size from the header first: a small file may declare a huge image.
        let (pw, ph) = read::png_size(&bytes).map_err(|r| {
            corrupt(
                seg,
                r,
                "a `_mask.png` must be an 8- or 16-bit greyscale or palette PNG of segment ids",
            )
        })?;
        if (pw, ph) != (w, h) {
            return Err(mismatch(seg, &[ph, pw], &[h, w]));
        }
        let img = read::png_labels(&bytes).map_err(|r| {
            corrupt(
                seg,
                r,
                "a `_mask.png` must be an 8- or 16-bit greyscale or palette PNG of segment ids",
            )
        })?;
        if (img.width, img.height) != (w, h) {
            return Err(mismatch(seg, &[img.height, img.width], &[h, w]));
        }
        labels_from_ids(seg, img.labels.iter().map(|&v| v as i64), n)?
    } else if name.ends_with(".npy") {
        let arr = read::npy(&bytes).map_err(|r| corrupt(seg, r, NPY_HINT))?;
        let kind = if arr.shape.len() == 2 {
            "labels"
        } else {
            "masks"
        };
        segmentation_from_array(seg, &arr, kind, hw, no_background)?
    } else {
        // Bounds before inflating: labels (H, W), masks at most MAX_SLOTS x (H, W), recon 3 x (H, W).
        let max_elements = |name: &str| {
            let per = match name {
                "masks" => MAX_SLOTS,
                "recon" => 3,
                _ => 1,
            };
            per.saturating_mul(w).saturating_mul(h)
        };
        let mut arrays = read::npz(&bytes, &["labels", "masks", "recon"], &max_elements)
            .map_err(|r| corrupt(seg, r, NPZ_HINT))?;
        if let Some(r) = arrays.remove("recon") {
            recon = Some(ReconImage::Unit(recon_from_array(seg, &r, hw)?));
        }
        match (arrays.get("labels"), arrays.get("masks")) {
            (Some(_), Some(_)) => {
                return Err(corrupt(
                    seg,
                    "it holds both `labels` and `masks`",
                    "keep one of them, so which prediction is scored is never a guess",
                ))
            }
            (Some(a), None) => segmentation_from_array(seg, a, "labels", hw, no_background)?,
            (None, Some(a)) => segmentation_from_array(seg, a, "masks", hw, no_background)?,
            (None, None) => {
                let names = read::npz_names(&bytes);
                return Err(corrupt(
                    seg,
                    format!(
                        "no `labels` or `masks` array (it holds: {})",
                        list_names(&names)
                    ),
                    "save the segmentation as `labels` (H, W) or `masks` (K, H, W)",
                ));
            }
        }
    };
    let mut read_bytes = vec![bytes];
    if let Some(rp) = &files.recon {
        if recon.is_some() {
            return Err(EvalError::Duplicate {
                what: "reconstruction",
                stem: name.to_string(),
                a: seg.clone(),
                b: rp.clone(),
            });
        }
        let rb = read_file(rp)?;
        let (pw, ph) = read::png_size(&rb)
            .map_err(|r| corrupt(rp, r, "a `_recon.png` must be an RGB(A) PNG"))?;
        if (pw, ph) != (w, h) {
            return Err(mismatch(rp, &[ph, pw, 3], &[h, w, 3]));
        }
        let img = read::png_rgb(&rb)
            .map_err(|r| corrupt(rp, r, "a `_recon.png` must be an RGB(A) PNG"))?;
        if (img.width, img.height) != (w, h) {
            return Err(mismatch(rp, &[img.height, img.width, 3], &[h, w, 3]));
        }
        recon = Some(ReconImage::Bytes(img.rgb));
        read_bytes.push(rb);
    }
    Ok((
        Prediction {
            labels,
            slots,
            recon,
        },
        read_bytes,
    ))
}
