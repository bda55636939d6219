//! Per-image metrics, as `docs/eval.md` defines them.

use serde::Serialize;

use crate::lsa::min_cost_assignment;

/// The ten dataset metrics, in report order.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize)]
pub enum Metric {
    /// Mean matched IoU over slots that are non-empty on either side (background included).
    MIoU,
    /// Mean matched IoU over foreground slots (the paper's tables).
    MIoUFg,
    /// Sum of matched IoU over the number of non-empty true segments.
    MIoUGt,
    /// Adjusted Rand index over all pixels.
    Ari,
    /// Adjusted Rand index over the true foreground pixels.
    AriFg,
    /// Per-image *sum* of squared reconstruction error over pixels and RGB channels.
    Mse,
    /// Mean matched Dice coefficient.
    Dice,
    /// Mean matched Dice coefficient over foreground slots.
    DiceFg,
    /// 1 when the numbers of non-empty true and predicted segments agree.
    Acc,
    /// Mean segmentation covering, weighted by true segment size.
    MSc,
}

impl Metric {
    /// All metrics, in report order.
    pub const ALL: [Metric; 10] = [
        Metric::MIoU,
        Metric::MIoUFg,
        Metric::MIoUGt,
        Metric::Ari,
        Metric::AriFg,
        Metric::Mse,
        Metric::Dice,
        Metric::DiceFg,
        Metric::Acc,
        Metric::MSc,
    ];

    /// The metric's name in reports, JSON and CSV.
    pub fn name(self) -> &'static str {
        match self {
            Metric::MIoU => "mIoU",
            Metric::MIoUFg => "mIoU_fg",
            Metric::MIoUGt => "mIoU_gt",
            Metric::Ari => "ARI",
            Metric::AriFg => "ARI_FG",
            Metric::Mse => "MSE",
            Metric::Dice => "DICE",
            Metric::DiceFg => "DICE_fg",
            Metric::Acc => "acc",
            Metric::MSc => "mSC",
        }
    }
}

/// The metrics of one image; `None` where a metric is undefined (never NaN).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Scores {
    /// Values indexed like [`Metric::ALL`].
    pub values: [Option<f64>; 10],
    /// Number of non-empty true segments (background included).
    pub true_segments: usize,
    /// Number of non-empty predicted segments.
    pub pred_segments: usize,
    /// Number of matched pairs where either side is non-empty.
    pub num_pairs: usize,
    /// Matched IoU of each true slot `t` (`iou_t`), for the per-object breakdown.
    pub iou_per_true: Vec<f64>,
    /// Pixels of each true slot.
    pub true_sizes: Vec<u64>,
    /// Squared error summed over each true slot's pixels and channels, when a reconstruction
    /// was given.
    pub sq_err_per_true: Option<Vec<f64>>,
}

impl Scores {
    /// The value of `metric`, `None` if undefined for this image.
    pub fn get(&self, metric: Metric) -> Option<f64> {
        self.values[Metric::ALL.iter().position(|&m| m == metric).unwrap_or(0)]
    }
}

/// A predicted image: floats in [0, 1], or 8-bit values (read as `v / 255` in f32).
#[derive(Clone, Copy, Debug)]
pub enum PredRgb<'a> {
    /// Interleaved RGB floats in [0, 1].
    Unit(&'a [f32]),
    /// Interleaved 8-bit RGB, as a `_recon.png` holds it.
    Bytes(&'a [u8]),
}

impl PredRgb<'_> {
    fn len(&self) -> usize {
        match self {
            PredRgb::Unit(v) => v.len(),
            PredRgb::Bytes(v) => v.len(),
        }
    }
}

/// Reconstruction input for MSE: the true image as 8-bit RGB and the prediction.
#[derive(Clone, Copy, Debug)]
pub struct Recon<'a> {
    /// True image, interleaved RGB, 8 bits per channel (`/ 255` gives the [0, 1] value).
    pub truth_rgb: &'a [u8],
    /// Predicted image, interleaved RGB.
    pub pred_rgb: PredRgb<'a>,
}

/// The exact f32 values of `v / 255`, as the reference divides.
fn unit_lut() -> [f32; 256] {
    std::array::from_fn(|v| v as f32 / 255.0)
}

/// Squared error per true slot and in total; difference and square in f32, sums in f64.
fn squared_errors(
    truth: &[u32],
    k: usize,
    truth_rgb: &[u8],
    pred: impl Fn(usize) -> f32,
) -> (f64, Vec<f64>) {
    let lut = unit_lut();
    let mut per_true = vec![0.0f64; k];
    let mut total = 0.0f64;
    for (i, &t) in truth.iter().enumerate() {
        let mut e = 0.0f64;
        for c in 0..3 {
            let d = pred(3 * i + c) - lut[truth_rgb[3 * i + c] as usize];
            e += (d * d) as f64;
        }
        per_true[t as usize] += e;
        total += e;
    }
    (total, per_true)
}

/// Compute every metric of one image from hard labels.
///
/// `truth` and `pred` are segment ids per pixel (same length). `pred_slots` is the number of
/// predicted slots (for hard labels, the largest id + 1; for soft masks, the number of masks);
/// it sets the size of the matching problem, which matters for scipy's tie-breaking.
/// Lengths that disagree give all-undefined scores rather than a panic; callers check shapes.
pub fn score_image(truth: &[u32], pred: &[u32], pred_slots: usize, recon: Option<Recon>) -> Scores {
    let n = truth.len();
    if pred.len() != n {
        return Scores::default();
    }
    let max_t = truth.iter().copied().max().map_or(0, |m| m as usize + 1);
    let max_p = pred.iter().copied().max().map_or(0, |m| m as usize + 1);
    let k = max_t.max(max_p).max(pred_slots).max(1);

    // Contingency counts, indexed [t * k + p].
    let mut counts = vec![0u64; k * k];
    for (&t, &p) in truth.iter().zip(pred) {
        counts[t as usize * k + p as usize] += 1;
    }
    let mut true_sizes = vec![0u64; k];
    let mut pred_sizes = vec![0u64; k];
    for t in 0..k {
        for p in 0..k {
            let c = counts[t * k + p];
            true_sizes[t] += c;
            pred_sizes[p] += c;
        }
    }

    // IoU in f32, exactly as the reference computes it; matrix indexed [t * k + p] (I^T).
    let mut iou = vec![0.0f32; k * k];
    for t in 0..k {
        for p in 0..k {
            let inter = counts[t * k + p];
            let union = true_sizes[t] + pred_sizes[p] - inter;
            if true_sizes[t] > 0 && pred_sizes[p] > 0 && union > 0 {
                iou[t * k + p] = inter as f32 / union as f32;
            }
        }
    }
    let cost: Vec<f64> = iou.iter().map(|&x| -(x as f64)).collect();
    let sigma = min_cost_assignment(k, &cost);

    let mut iou_per_true = vec![0.0f64; k];
    let mut dice_per_true = vec![0.0f64; k];
    let mut num_pairs = 0usize;
    for t in 0..k {
        let p = sigma[t].min(k - 1);
        iou_per_true[t] = iou[t * k + p] as f64;
        let denom = pred_sizes[p] + true_sizes[t];
        if denom > 0 {
            dice_per_true[t] = 2.0 * counts[t * k + p] as f64 / denom as f64;
        }
        if true_sizes[t] > 0 || pred_sizes[p] > 0 {
            num_pairs += 1;
        }
    }
    let true_segments = true_sizes.iter().filter(|&&s| s > 0).count();
    let pred_segments = pred_sizes.iter().filter(|&&s| s > 0).count();

    let ratio = |num: f64, den: usize| (den > 0).then(|| num / den as f64);
    let sum_all = |v: &[f64]| v.iter().sum::<f64>();
    let sum_fg = |v: &[f64]| v.iter().skip(1).sum::<f64>();

    let miou = ratio(sum_all(&iou_per_true), num_pairs);
    let miou_fg = ratio(sum_fg(&iou_per_true), num_pairs.saturating_sub(1));
    let miou_gt = ratio(sum_all(&iou_per_true), true_segments);
    let dice = ratio(sum_all(&dice_per_true), num_pairs);
    let dice_fg = ratio(sum_fg(&dice_per_true), num_pairs.saturating_sub(1));
    let acc = (n > 0).then_some(if true_segments == pred_segments {
        1.0
    } else {
        0.0
    });

    // ARI over all pixels and over true foreground pixels, from the contingency table.
    let (ari, ari_fg) = if n > 0 {
        (
            Some(ari_from_counts(&counts, k, 0)),
            Some(ari_from_counts(&counts, k, 1)),
        )
    } else {
        (None, None)
    };

    // Segmentation covering: true-size-weighted best IoU of each true segment.
    let mut covered = 0.0f64;
    for t in 0..k {
        if true_sizes[t] > 0 {
            let best = (0..k).map(|p| iou[t * k + p]).fold(0.0f32, f32::max);
            covered += true_sizes[t] as f64 * best as f64;
        }
    }
    let msc = (n > 0).then(|| covered / n as f64);

    let (mse, sq_err_per_true) = match recon {
        Some(r) if r.truth_rgb.len() == 3 * n && r.pred_rgb.len() == 3 * n => {
            let (total, per_true) = match r.pred_rgb {
                PredRgb::Unit(p) => squared_errors(truth, k, r.truth_rgb, |i| p[i]),
                PredRgb::Bytes(p) => {
                    let lut = unit_lut();
                    squared_errors(truth, k, r.truth_rgb, |i| lut[p[i] as usize])
                }
            };
            (total.is_finite().then_some(total), Some(per_true))
        }
        _ => (None, None),
    };

    Scores {
        values: [
            miou, miou_fg, miou_gt, ari, ari_fg, mse, dice, dice_fg, acc, msc,
        ],
        true_segments,
        pred_segments,
        num_pairs,
        iou_per_true,
        true_sizes,
        sq_err_per_true,
    }
}

/// Adjusted Rand index of the contingency table `counts` (`k x k`, `[t * k + p]`) restricted to
/// true rows `t >= first_row`, in exact integer arithmetic (scikit-learn's current semantics).
pub fn ari_from_counts(counts: &[u64], k: usize, first_row: usize) -> f64 {
    let mut n: i128 = 0;
    let mut s: i128 = 0;
    let mut a: i128 = 0;
    let mut col = vec![0i128; k];
    for t in first_row..k {
        let mut row: i128 = 0;
        for p in 0..k {
            let c = counts[t * k + p] as i128;
            s += c * c;
            row += c;
            col[p] += c;
        }
        a += row * row;
        n += row;
    }
    let b: i128 = col.iter().map(|c| c * c).sum();
    ari_from_sums(n, s, a, b)
}

/// ARI from `n` pixels, `s = Σ n_ij²`, `a = Σ a_i²` (true), `b = Σ b_j²` (predicted).
pub fn ari_from_sums(n: i128, s: i128, a: i128, b: i128) -> f64 {
    let tp = s - n;
    let fp = b - s;
    let fn_ = a - s;
    let tn = n * n - fp - fn_ - s;
    if fn_ == 0 && fp == 0 {
        return 1.0;
    }
    // i128 holds these for images up to 2^31 pixels; beyond that fall back to f64.
    let exact = || -> Option<(i128, i128)> {
        let num = tp.checked_mul(tn)?.checked_sub(fn_.checked_mul(fp)?)?;
        let d1 = (tp + fn_).checked_mul(fn_ + tn)?;
        let d2 = (tp + fp).checked_mul(fp + tn)?;
        Some((num, d1.checked_add(d2)?))
    };
    let score = match exact() {
        // Same rounding as Python's `2.0 * int / int`.
        Some((num, den)) => 2.0 * (num as f64) / (den as f64),
        None => {
            let (tp, fp, fn_, tn) = (tp as f64, fp as f64, fn_ as f64, tn as f64);
            2.0 * (tp * tn - fn_ * fp) / ((tp + fn_) * (fn_ + tn) + (tp + fp) * (fp + tn))
        }
    };
    if score.is_finite() {
        score
    } else {
        0.0
    }
}
