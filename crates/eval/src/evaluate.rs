//! Evaluating a predictions directory against a ground-truth dataset, in parallel over images.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use rand::{Rng, SeedableRng};
use rayon::prelude::*;
use xxhash_rust::xxh3::xxh3_64;

use crate::dataset::{discover_gt, index_preds, Split};
use crate::error::EvalError;
use crate::image::score_sample;
pub use crate::image::{ImageResult, ObjectScore, ReconIssue};
use crate::metrics::{Metric, METRICS};
pub use crate::protocol::{Options, Protocol};

/// Mean, confidence interval and count of one metric over the dataset.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Summary {
    /// Mean over images where the metric is defined; `None` if it is defined nowhere.
    pub mean: Option<f64>,
    /// 95% percentile-bootstrap interval, when requested and defined.
    pub ci: Option<(f64, f64)>,
    /// Images where the metric is defined.
    pub defined: usize,
}

/// Mean IoU and MSE of one breakdown group.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Group {
    /// Number of objects.
    pub count: usize,
    /// Mean matched IoU.
    pub iou: f64,
    /// Mean best overlap (the objects' share of `mBO`).
    pub best_overlap: f64,
    /// Mean per-object squared error, over objects with a reconstruction.
    pub mse: Option<f64>,
    /// Objects with a reconstruction.
    pub mse_count: usize,
}

/// A finished evaluation.
#[derive(Clone, Debug)]
pub struct Report {
    /// Variant evaluated.
    pub variant: String,
    /// Split evaluated.
    pub split: Split,
    /// Protocol used.
    pub protocol: Protocol,
    /// Soft masks had no background slot.
    pub no_background: bool,
    /// Per-image results, in index order.
    pub images: Vec<ImageResult>,
    /// Per-metric summaries, indexed like [`Metric::ALL`].
    pub summaries: [Summary; METRICS],
    /// The metrics reported, in report order.
    pub metrics: Vec<Metric>,
    /// Ground truth was cropped and resized to 128x128.
    pub cropped: bool,
    /// Breakdowns: kind (`material`, `shape`, `size`, `color`, `ground_material`) -> value ->
    /// group.
    pub breakdowns: BTreeMap<&'static str, BTreeMap<String, Group>>,
    /// Bootstrap resamples used.
    pub bootstrap: usize,
    /// Bootstrap seed.
    pub seed: u64,
    /// Hash of all ground-truth files read (xxh3 of the per-image hashes).
    pub gt_hash: u64,
    /// Hash of all prediction files read.
    pub pred_hash: u64,
    /// Ground-truth directory.
    pub gt_dir: PathBuf,
    /// Predictions directory.
    pub pred_dir: PathBuf,
}

impl Report {
    /// Images scored without a prediction.
    pub fn missing(&self) -> usize {
        self.images.iter().filter(|i| i.missing).count()
    }

    /// Images whose reconstruction made MSE undefined (NaN, infinite or overflowing).
    pub fn recon_undefined(&self) -> usize {
        let bad = |i: &&ImageResult| matches!(i.recon_issue, Some(ReconIssue::Undefined { .. }));
        self.images.iter().filter(bad).count()
    }

    /// Images whose reconstruction held values outside [0, 1].
    pub fn recon_out_of_range(&self) -> usize {
        let bad = |i: &&ImageResult| matches!(i.recon_issue, Some(ReconIssue::OutOfRange { .. }));
        self.images.iter().filter(bad).count()
    }

    /// Metadata objects whose label did not occur.
    pub fn objects_skipped(&self) -> usize {
        self.images.iter().map(|i| i.objects_skipped).sum()
    }

    /// Summary of one metric.
    pub fn summary(&self, m: Metric) -> Summary {
        self.summaries[m.index()]
    }
}

/// Most bootstrap resamples (each costs one pass over the images and 80 bytes).
pub const MAX_BOOTSTRAP: usize = 100_000;

/// Evaluate the predictions under `preds` against the dataset under `gt`.
pub fn evaluate(preds: &Path, gt: &Path, opts: &Options) -> Result<Report, EvalError> {
    if opts.bootstrap > MAX_BOOTSTRAP {
        return Err(EvalError::Usage {
            message: format!(
                "`--bootstrap {}` is more than the {MAX_BOOTSTRAP} resamples allowed",
                opts.bootstrap
            ),
            hint: "1000 (the default) gives stable 95% intervals; use at most 100000".into(),
        });
    }
    let (variant, mut samples) = discover_gt(gt, opts.variant.as_deref())?;
    // A test-only variant (its config says `"splits": "test_only"`) is scored whole.
    let split = opts
        .split
        .unwrap_or(match clevrtex_dataset::layout::variant_splits(&variant) {
            clevrtex_scene::config::Splits::TestOnly => Split::All,
            clevrtex_scene::config::Splits::Standard => Split::Test,
        });
    if split.part().is_some() {
        crate::dataset::read_splits(gt, &variant, &mut samples)?;
    }
    let all = &samples;
    let samples = split.select(all, &variant)?;
    if samples.is_empty() {
        return Err(EvalError::EmptySplit {
            split: split.name(),
            gt: gt.to_path_buf(),
            total: all.len(),
            sizes: crate::dataset::split_sizes(all),
        });
    }
    let pred_index = index_preds(preds, &variant)?;
    let by_colour = clevrtex_dataset::layout::variant_colour_breakdown(&variant);
    let missing: Vec<&str> = samples
        .iter()
        .filter(|s| {
            pred_index
                .get(&s.stem)
                .is_none_or(|p| p.segmentation.is_none())
        })
        .map(|s| s.stem.as_str())
        .collect();
    if !missing.is_empty() && !opts.allow_missing {
        return Err(EvalError::MissingPredictions {
            count: missing.len(),
            total: samples.len(),
            first: missing.iter().take(5).map(|s| s.to_string()).collect(),
            skipped: missing
                .iter()
                .filter_map(|s| pred_index.get(*s).and_then(|p| p.skipped.clone()))
                .take(5)
                .collect(),
        });
    }

    let images = samples
        .par_iter()
        .map(|s| {
            let files = pred_index.get(&s.stem).cloned().unwrap_or_default();
            score_sample(s, &files, by_colour, opts)
        })
        .collect::<Result<Vec<_>, _>>()?;

    let values: Vec<[Option<f64>; METRICS]> = images.iter().map(|r| r.scores.values).collect();
    let summaries = summarise(&values, opts.bootstrap, opts.seed);

    // kind -> value -> (objects, IoU sum, objects with MSE, MSE sum, best-overlap sum)
    type Sums = BTreeMap<&'static str, BTreeMap<String, (usize, f64, usize, f64, f64)>>;
    let mut sums: Sums = BTreeMap::new();
    for r in &images {
        for o in &r.objects {
            for (kind, value) in &o.groups {
                let g = sums
                    .entry(kind)
                    .or_default()
                    .entry(value.clone())
                    .or_default();
                g.0 += 1;
                g.1 += o.iou;
                g.4 += o.best_overlap;
                if let Some(e) = o.mse {
                    g.2 += 1;
                    g.3 += e;
                }
            }
        }
    }
    let breakdowns = sums
        .into_iter()
        .map(|(k, groups)| {
            let groups = groups
                .into_iter()
                .map(|(v, (n, iou, mn, mse, bo))| {
                    let g = Group {
                        count: n,
                        iou: iou / n as f64,
                        best_overlap: bo / n as f64,
                        mse: (mn > 0).then(|| mse / mn as f64),
                        mse_count: mn,
                    };
                    (v, g)
                })
                .collect();
            (k, groups)
        })
        .collect();

    let cat = |f: fn(&ImageResult) -> u64| {
        let bytes: Vec<u8> = images.iter().flat_map(|r| f(r).to_le_bytes()).collect();
        xxh3_64(&bytes)
    };
    Ok(Report {
        gt_hash: cat(|r| r.gt_hash),
        pred_hash: cat(|r| r.pred_hash),
        variant,
        split,
        protocol: opts.protocol,
        metrics: if opts.metrics.is_empty() {
            opts.protocol.default_metrics().to_vec()
        } else {
            opts.metrics.clone()
        },
        cropped: opts.crops(),
        no_background: opts.no_background,
        images,
        summaries,
        breakdowns,
        bootstrap: opts.bootstrap,
        seed: opts.seed,
        gt_dir: gt.to_path_buf(),
        pred_dir: preds.to_path_buf(),
    })
}

/// Per metric: the mean over images where it is defined, and a 95% percentile bootstrap over
/// images. Each resample draws image indices once for all metrics; resample `r` uses ChaCha
/// stream `r` of `seed`, so the intervals do not depend on the number of threads.
pub fn summarise(
    values: &[[Option<f64>; METRICS]],
    bootstrap: usize,
    seed: u64,
) -> [Summary; METRICS] {
    let n = values.len();
    let mut out = [Summary::default(); METRICS];
    for (m, s) in out.iter_mut().enumerate() {
        let defined: Vec<f64> = values.iter().filter_map(|v| v[m]).collect();
        if !defined.is_empty() {
            s.mean = Some(defined.iter().sum::<f64>() / defined.len() as f64);
            s.defined = defined.len();
        }
    }
    if bootstrap == 0 || n == 0 {
        return out;
    }
    let resamples: Vec<[Option<f64>; METRICS]> = (0..bootstrap)
        .into_par_iter()
        .map(|r| {
            let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
            rng.set_stream(r as u64);
            let mut sum = [0.0f64; METRICS];
            let mut count = [0usize; METRICS];
            for _ in 0..n {
                let v = &values[rng.random_range(0..n)];
                for m in 0..METRICS {
                    if let Some(x) = v[m] {
                        sum[m] += x;
                        count[m] += 1;
                    }
                }
            }
            std::array::from_fn(|m| (count[m] > 0).then(|| sum[m] / count[m] as f64))
        })
        .collect();
    for (m, s) in out.iter_mut().enumerate() {
        let mut means: Vec<f64> = resamples.iter().filter_map(|r| r[m]).collect();
        if means.is_empty() {
            continue;
        }
        means.sort_by(f64::total_cmp);
        let (lo, hi) = (percentile(&means, 2.5), percentile(&means, 97.5));
        if lo.is_finite() && hi.is_finite() {
            s.ci = Some((lo, hi));
        }
    }
    out
}

/// Linear-interpolation percentile of sorted values (numpy's default).
fn percentile(sorted: &[f64], q: f64) -> f64 {
    if sorted.is_empty() {
        return f64::NAN;
    }
    let pos = q / 100.0 * (sorted.len() - 1) as f64;
    let lo = pos.floor() as usize;
    let hi = pos.ceil() as usize;
    sorted[lo] + (sorted[hi] - sorted[lo]) * (pos - lo as f64)
}
