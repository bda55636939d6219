//! Per-image metrics, as `docs/eval.md` defines them.

use serde::Serialize;

use crate::lsa::min_cost_assignment;

/// Every dataset metric of every protocol, in report order (`docs/eval.md` defines them and
/// names the code each one equals).
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
    /// DeepMind's FG-ARI (`multi_object_datasets/segmentation_metrics.py`): ARI over pixels
    /// with a true object, 1 when both partitions are one cluster, undefined where the
    /// original divides 0 by 0.
    DmFgAri,
    /// The object-centric learning framework's ARI over all pixels (`ARIMetric(foreground=False)`).
    OclAri,
    /// Its ARI over true-object pixels (`ARIMetric(foreground=True)`), 1 where degenerate.
    OclFgAri,
    /// Its Hungarian-matched IoU per non-empty true segment, background included
    /// (`UnsupervisedMaskIoUMetric(matching="hungarian")`).
    OclMIoU,
    /// The same over the true objects only (`ignore_background=True`).
    OclMIoUFg,
    /// Mean best overlap: per true object the best IoU over the predicted masks, averaged
    /// (`UnsupervisedMaskIoUMetric(matching="best_overlap", ignore_background=True)`).
    MBo,
    /// 1 when some true object has a best overlap above 0.5 (`MaskCorLocMetric`, objects only).
    CorLoc,
}

/// Number of metrics in [`Metric::ALL`].
pub const METRICS: usize = 17;

/// The protocol family whose metrics these are: `clevrtex` (and `native`), `deepmind`, `ocl`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Family {
    /// The public ClevrTex evaluator's.
    Clevrtex,
    /// DeepMind's `multi_object_datasets`.
    Deepmind,
    /// The object-centric learning framework's.
    Ocl,
}

/// One row of the metric table.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct MetricSpec {
    /// The metric.
    pub metric: Metric,
    /// Its name in reports, JSON, CSV and the Python package.
    pub name: &'static str,
    /// The protocol family that reports it by default.
    pub family: Family,
    /// Decimals in the report's table (and its confidence interval).
    pub decimals: usize,
}

/// The metric table, in report order (the order of [`Metric`]'s variants, checked at compile
/// time): every list of metrics (all, each protocol's) and every name comes from here.
#[rustfmt::skip]
pub const TABLE: [MetricSpec; METRICS] = [
    MetricSpec { metric: Metric::MIoU, name: "mIoU", family: Family::Clevrtex, decimals: 6 },
    MetricSpec { metric: Metric::MIoUFg, name: "mIoU_fg", family: Family::Clevrtex, decimals: 6 },
    MetricSpec { metric: Metric::MIoUGt, name: "mIoU_gt", family: Family::Clevrtex, decimals: 6 },
    MetricSpec { metric: Metric::Ari, name: "ARI", family: Family::Clevrtex, decimals: 6 },
    MetricSpec { metric: Metric::AriFg, name: "ARI_FG", family: Family::Clevrtex, decimals: 6 },
    MetricSpec { metric: Metric::Mse, name: "MSE", family: Family::Clevrtex, decimals: 4 },
    MetricSpec { metric: Metric::Dice, name: "DICE", family: Family::Clevrtex, decimals: 6 },
    MetricSpec { metric: Metric::DiceFg, name: "DICE_fg", family: Family::Clevrtex, decimals: 6 },
    MetricSpec { metric: Metric::Acc, name: "acc", family: Family::Clevrtex, decimals: 6 },
    MetricSpec { metric: Metric::MSc, name: "mSC", family: Family::Clevrtex, decimals: 6 },
    MetricSpec { metric: Metric::DmFgAri, name: "dm_FG_ARI", family: Family::Deepmind, decimals: 6 },
    MetricSpec { metric: Metric::OclAri, name: "ocl_ARI", family: Family::Ocl, decimals: 6 },
    MetricSpec { metric: Metric::OclFgAri, name: "ocl_FG_ARI", family: Family::Ocl, decimals: 6 },
    MetricSpec { metric: Metric::OclMIoU, name: "ocl_mIoU", family: Family::Ocl, decimals: 6 },
    MetricSpec { metric: Metric::OclMIoUFg, name: "ocl_mIoU_fg", family: Family::Ocl, decimals: 6 },
    MetricSpec { metric: Metric::MBo, name: "mBO", family: Family::Ocl, decimals: 6 },
    MetricSpec { metric: Metric::CorLoc, name: "CorLoc", family: Family::Ocl, decimals: 6 },
];

const _: () = {
    let mut i = 0;
    while i < METRICS {
        assert!(TABLE[i].metric as usize == i, "TABLE is in Metric's order");
        i += 1;
    }
};

/// The metrics of `family`, in table order; `N` must be their number (checked at compile time).
const fn family<const N: usize>(family: Family) -> [Metric; N] {
    let mut out = [Metric::MIoU; N];
    let (mut i, mut n) = (0, 0);
    while i < METRICS {
        if TABLE[i].family as u8 == family as u8 {
            assert!(n < N, "more metrics of the family than N");
            out[n] = TABLE[i].metric;
            n += 1;
        }
        i += 1;
    }
    assert!(n == N, "fewer metrics of the family than N");
    out
}

impl Metric {
    /// The `clevrtex` protocol's metrics (the public ClevrTex evaluator's), in report order.
    pub const CLEVRTEX: [Metric; 10] = family(Family::Clevrtex);

    /// The `deepmind` protocol's metrics.
    pub const DEEPMIND: [Metric; 1] = family(Family::Deepmind);

    /// The `ocl` protocol's metrics.
    pub const OCL: [Metric; 6] = family(Family::Ocl);

    /// Every metric, in report order: the `clevrtex` ones, then `deepmind`'s, then `ocl`'s.
    pub const ALL: [Metric; METRICS] = {
        let mut out = [Metric::MIoU; METRICS];
        let mut i = 0;
        while i < METRICS {
            out[i] = TABLE[i].metric;
            i += 1;
        }
        out
    };

    /// Position in [`Metric::ALL`] (and in [`Scores::values`]).
    pub fn index(self) -> usize {
        self as usize
    }

    /// The metric's row in [`TABLE`].
    pub fn spec(self) -> &'static MetricSpec {
        &TABLE[self.index()]
    }

    /// The metric called `name` (as in reports), if any.
    pub fn from_name(name: &str) -> Option<Metric> {
        TABLE.iter().find(|s| s.name == name).map(|s| s.metric)
    }

    /// The metric's name in reports, JSON and CSV.
    pub fn name(self) -> &'static str {
        self.spec().name
    }
}

/// The metrics of one image; `None` where a metric is undefined (never NaN).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Scores {
    /// Values indexed like [`Metric::ALL`].
    pub values: [Option<f64>; METRICS],
    /// Number of non-empty true segments (background included).
    pub true_segments: usize,
    /// Number of non-empty predicted segments.
    pub pred_segments: usize,
    /// Number of matched pairs where either side is non-empty.
    pub num_pairs: usize,
    /// Matched IoU of each true slot `t` (`iou_t`), for the per-object breakdown.
    pub iou_per_true: Vec<f64>,
    /// Best overlap (largest IoU over predicted segments, in f64 as the `ocl` protocol
    /// computes it) of each true slot, 0 for empty ones; for the per-object breakdown.
    pub best_overlap_per_true: Vec<f64>,
    /// Pixels of each true slot.
    pub true_sizes: Vec<u64>,
    /// Squared error summed over each true slot's pixels and channels, when a reconstruction
    /// was given.
    pub sq_err_per_true: Option<Vec<f64>>,
}

impl Scores {
    /// The value of `metric`, `None` if undefined for this image.
    pub fn get(&self, metric: Metric) -> Option<f64> {
        self.values[metric.index()]
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

/// Pixels per block of the squared-error and argmax kernels: a block's values stay in L1.
pub const BLOCK: usize = 256;

/// Squared error per true slot (`k` slots, each label of `truth` below `k`) and in total: the
/// one MSE kernel of `clevrtex eval` and the Python package. `add_block(start, e)` adds to
/// `e[j]` the error of pixel `start + j`, channel by channel (difference and square in f32,
/// each square added in f64); the pixels' errors are then summed in pixel order in f64. Blocked
/// over pixels, so that `add_block`'s loop can vectorise.
pub fn squared_errors(
    truth: &[u32],
    k: usize,
    mut add_block: impl FnMut(usize, &mut [f64]),
) -> (f64, Vec<f64>) {
    let mut per_true = vec![0.0f64; k];
    let mut total = 0.0f64;
    let mut e = [0.0f64; BLOCK];
    let (mut label, mut run) = (0usize, 0.0f64);
    for (start, t) in (0..truth.len()).step_by(BLOCK).zip(truth.chunks(BLOCK)) {
        let e = &mut e[..t.len()];
        e.fill(0.0);
        add_block(start, e);
        for (&l, &e) in t.iter().zip(e.iter()) {
            // The running sum of a run of one label stays in a register (same additions in
            // the same order as `per_true[l] += e`, without a store-to-load wait per pixel).
            if l as usize != label {
                per_true[label] = run;
                label = l as usize;
                run = per_true[label];
            }
            run += e;
            total += e;
        }
    }
    if !per_true.is_empty() {
        per_true[label] = run;
    }
    (total, per_true)
}

/// [`squared_errors`]' block function for interleaved RGB: 8-bit truth (`v / 255`) against
/// `pred(i)`, the value at interleaved position `i`.
fn interleaved_errors<'a>(
    truth_rgb: &'a [u8],
    pred: impl Fn(usize) -> f32 + 'a,
) -> impl FnMut(usize, &mut [f64]) + 'a {
    let lut = unit_lut();
    move |start, e| {
        for (j, e) in e.iter_mut().enumerate() {
            let i = 3 * (start + j);
            for c in 0..3 {
                let d = pred(i + c) - lut[truth_rgb[i + c] as usize];
                *e += (d * d) as f64;
            }
        }
    }
}

/// Contingency counts of `truth` against `pred` (labels below `k`), indexed `[t * k + p]`.
fn contingency(truth: &[u32], pred: &[u32], k: usize) -> Vec<u64> {
    let mut counts = vec![0u64; k * k];
    if k > 64 || truth.len() >= u32::MAX as usize {
        for (&t, &p) in truth.iter().zip(pred) {
            counts[t as usize * k + p as usize] += 1;
        }
        return counts;
    }
    // Four small tables, one per pixel mod 4, summed after: with one table, a run of pixels
    // with the same (t, p) waits on its own count's store at every pixel.
    let kk = k * k;
    let mut tables = vec![0u32; 4 * kk];
    let (t4, p4) = (truth.chunks_exact(4), pred.chunks_exact(4));
    for (&t, &p) in t4.remainder().iter().zip(p4.remainder()) {
        tables[t as usize * k + p as usize] += 1;
    }
    for (t, p) in t4.zip(p4) {
        for j in 0..4 {
            tables[j * kk + t[j] as usize * k + p[j] as usize] += 1;
        }
    }
    for (j, c) in counts.iter_mut().enumerate() {
        *c = (0..4).map(|q| u64::from(tables[q * kk + j])).sum();
    }
    counts
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

    let counts = contingency(truth, pred, k);
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

    let (dm_fg_ari, ocl_ari, ocl_fg_ari) = if n > 0 {
        let single = true_sizes.iter().skip(2).all(|&s| s == 0) && pred_segments <= 1;
        (
            dm_fg_ari(&counts, k, single),
            Some(ocl_ari(&counts, k, 0)),
            Some(ocl_ari(&counts, k, 1)),
        )
    } else {
        (None, None, None)
    };
    let ocl = ocl_iou(&counts, k, &true_sizes, &pred_sizes);

    let values = [
        miou,
        miou_fg,
        miou_gt,
        ari,
        ari_fg,
        None, // MSE, below
        dice,
        dice_fg,
        acc,
        msc,
        dm_fg_ari,
        ocl_ari,
        ocl_fg_ari,
        ocl.miou,
        ocl.miou_fg,
        ocl.mbo,
        ocl.corloc,
    ];

    let (mse, sq_err_per_true) = match recon {
        Some(r) if r.truth_rgb.len() == 3 * n && r.pred_rgb.len() == 3 * n => {
            let (total, per_true) = match r.pred_rgb {
                PredRgb::Unit(p) => {
                    squared_errors(truth, k, interleaved_errors(r.truth_rgb, |i| p[i]))
                }
                PredRgb::Bytes(p) => {
                    let lut = unit_lut();
                    let pred = |i: usize| lut[p[i] as usize];
                    squared_errors(truth, k, interleaved_errors(r.truth_rgb, pred))
                }
            };
            (total.is_finite().then_some(total), Some(per_true))
        }
        _ => (None, None),
    };

    let mut values = values;
    values[Metric::Mse.index()] = mse;
    Scores {
        values,
        true_segments,
        pred_segments,
        num_pairs,
        iou_per_true,
        best_overlap_per_true: ocl.best_overlap,
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

/// Pair counts `Σ n(n - 1)` of the contingency table restricted to true rows `>= first_row`:
/// `(rindex, aindex (true), bindex (predicted), points)`, exact.
fn pair_indices(counts: &[u64], k: usize, first_row: usize) -> (i128, i128, i128, i128) {
    let (mut r, mut a, mut n) = (0i128, 0i128, 0i128);
    let mut col = vec![0i128; k];
    for t in first_row..k {
        let mut row = 0i128;
        for p in 0..k {
            let c = counts[t * k + p] as i128;
            r += c * (c - 1);
            row += c;
            col[p] += c;
        }
        a += row * (row - 1);
        n += row;
    }
    let b = col.iter().map(|c| c * (c - 1)).sum();
    (r, a, b, n)
}

/// DeepMind's FG-ARI of one image: ARI over the pixels with a true object (rows `t >= 1`).
/// The original (`segmentation_metrics.py`) returns 1 when the true group ids (the argmax of
/// a one-hot without the background, so background and object 1 share id 0) and the predicted
/// ids are each constant over *all* pixels (`single`); otherwise it divides, and where the
/// divisor is zero (one object predicted whole, or no object pixels) it yields NaN: undefined
/// here. Computed exactly; the original's float32 differs by rounding only.
fn dm_fg_ari(counts: &[u64], k: usize, single: bool) -> Option<f64> {
    if single {
        return Some(1.0);
    }
    let (r, a, b, n) = pair_indices(counts, k, 1);
    let pairs = n * (n - 1);
    // ari = (r - a b / N) / ((a + b) / 2 - a b / N) = 2 (r N - a b) / ((a + b) N - 2 a b).
    let num = r.checked_mul(pairs)?.checked_sub(a.checked_mul(b)?)?;
    let den = (a + b)
        .checked_mul(pairs)?
        .checked_sub(2 * a.checked_mul(b)?)?;
    if pairs == 0 || den == 0 {
        return None;
    }
    Some(2.0 * num as f64 / den as f64)
}

/// The object-centric learning framework's ARI (`ocl/metrics/utils.py`) over true rows
/// `t >= first_row`, with its float64 operations in its order (so the same rounding), and its
/// degenerate value: 1 wherever the divisor is not positive.
fn ocl_ari(counts: &[u64], k: usize, first_row: usize) -> f64 {
    let (r, a, b, n) = pair_indices(counts, k, first_row);
    let (r, a, b) = (r as f64, a as f64, b as f64);
    let pairs = ((n * (n - 1)) as f64).max(1.0);
    let expected = a * b / pairs;
    let max = (a + b) / 2.0;
    let den = max - expected;
    if den > 0.0 {
        (r - expected) / den
    } else {
        1.0
    }
}

/// The `ocl` protocol's IoU metrics of one image.
struct OclIou {
    miou: Option<f64>,
    miou_fg: Option<f64>,
    mbo: Option<f64>,
    corloc: Option<f64>,
    best_overlap: Vec<f64>,
}

/// `UnsupervisedMaskIoUMetric` (`ocl/metrics/masks.py`): IoU in f64 between every predicted
/// slot and every non-empty true segment; `hungarian` averages the optimally matched IoU over
/// the true segments (an unmatched one counts 0; the optimum's total does not depend on ties),
/// `best_overlap` the largest IoU of each. An image without a true segment is skipped by the
/// original (left out of the mean): undefined here.
fn ocl_iou(counts: &[u64], k: usize, true_sizes: &[u64], pred_sizes: &[u64]) -> OclIou {
    let iou = |t: usize, p: usize| {
        let inter = counts[t * k + p];
        let union = true_sizes[t] + pred_sizes[p] - inter;
        if union == 0 {
            0.0
        } else {
            inter as f64 / union as f64
        }
    };
    let best_overlap: Vec<f64> = (0..k)
        .map(|t| {
            if true_sizes[t] == 0 {
                return 0.0;
            }
            (0..k).map(|p| iou(t, p)).fold(0.0, f64::max)
        })
        .collect();
    let hungarian = |first: usize| -> Option<f64> {
        let rows = (first..k).filter(|&t| true_sizes[t] > 0).count();
        if rows == 0 {
            return None;
        }
        // Empty (or left-out) true rows cost 0 whatever they get, so the square problem has
        // the rectangular one's optimum.
        let mut cost = vec![0.0f64; k * k];
        for t in (first..k).filter(|&t| true_sizes[t] > 0) {
            for p in 0..k {
                cost[t * k + p] = -iou(t, p);
            }
        }
        let sigma = min_cost_assignment(k, &cost);
        let total: f64 = (first..k)
            .filter(|&t| true_sizes[t] > 0)
            .map(|t| iou(t, sigma[t].min(k - 1)))
            .sum();
        Some(total / rows as f64)
    };
    let objects: Vec<f64> = (1..k)
        .filter(|&t| true_sizes[t] > 0)
        .map(|t| best_overlap[t])
        .collect();
    let (mbo, corloc) = if objects.is_empty() {
        (None, None)
    } else {
        let found = objects.iter().any(|&v| v > 0.5);
        (
            Some(objects.iter().sum::<f64>() / objects.len() as f64),
            Some(if found { 1.0 } else { 0.0 }),
        )
    };
    OclIou {
        miou: hungarian(0),
        miou_fg: hungarian(1),
        mbo,
        corloc,
        best_overlap,
    }
}
