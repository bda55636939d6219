//! Evaluating a predictions directory against a ground-truth dataset, in parallel over images.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use rand::{Rng, SeedableRng};
use rayon::prelude::*;
use xxhash_rust::xxh3::xxh3_64;

use crate::dataset::{discover_gt, index_preds, PredFiles, Split};
use crate::error::{corrupt, EvalError, MAX_SLOTS};
use crate::metrics::{score_image, Metric, Recon, Scores, METRICS};
use crate::resize::{crop_resize_bilinear_rgb, crop_resize_nearest, EVAL_SIDE};
use crate::{meta, predict, read};

/// Which community's metrics are reported by default, and how ground truth is brought to the
/// predictions' resolution (`docs/eval.md` has a table of how the protocols differ).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Protocol {
    /// The public ClevrTex evaluator's metrics; centre crop of side `int(0.8 min(W, H))`,
    /// resized to 128x128 (the benchmark's).
    Clevrtex,
    /// The ClevrTex metrics without crop or resize: predictions at the ground truth's
    /// resolution.
    Native,
    /// DeepMind's FG-ARI (`multi_object_datasets/segmentation_metrics.py`); same crop and resize
    /// as `clevrtex`.
    Deepmind,
    /// The object-centric learning framework's ARI, mIoU, mBO and CorLoc
    /// (`ocl/metrics/masks.py`); same crop and resize as `clevrtex`.
    Ocl,
}

impl Protocol {
    /// Name as on the command line.
    pub fn name(self) -> &'static str {
        match self {
            Protocol::Clevrtex => "clevrtex",
            Protocol::Native => "native",
            Protocol::Deepmind => "deepmind",
            Protocol::Ocl => "ocl",
        }
    }

    /// The protocol called `name`, if any.
    pub fn from_name(name: &str) -> Option<Protocol> {
        [
            Protocol::Clevrtex,
            Protocol::Native,
            Protocol::Deepmind,
            Protocol::Ocl,
        ]
        .into_iter()
        .find(|p| p.name() == name)
    }

    /// The metrics reported when none are chosen.
    pub fn default_metrics(self) -> &'static [Metric] {
        match self {
            Protocol::Clevrtex | Protocol::Native => &Metric::CLEVRTEX,
            Protocol::Deepmind => &Metric::DEEPMIND,
            Protocol::Ocl => &Metric::OCL,
        }
    }

    /// Whether ground truth is centre-cropped and resized to 128x128 (unless the options ask
    /// for the native size).
    pub fn crops(self) -> bool {
        self != Protocol::Native
    }

    /// Where the protocol's definitions come from, for the report's header.
    pub fn source(self) -> &'static str {
        match self {
            Protocol::Clevrtex | Protocol::Native => {
                "karazijal/clevrtex `CLEVRTEX_Evaluator` (ool/clevrtex_eval.py)"
            }
            Protocol::Deepmind => {
                "deepmind/multi_object_datasets `adjusted_rand_index` (segmentation_metrics.py)"
            }
            Protocol::Ocl => {
                "amazon-science/object-centric-learning-framework (ocl/metrics/masks.py)"
            }
        }
    }
}

/// Options of an evaluation.
#[derive(Clone, Debug)]
pub struct Options {
    /// Protocol: the default metrics and the crop/resize.
    pub protocol: Protocol,
    /// Metrics to report; empty for the protocol's own.
    pub metrics: Vec<Metric>,
    /// Score at the dataset's own resolution whatever the protocol (no crop, no resize).
    pub native_size: bool,
    /// Which split; `None` is the default (`test`; all of `outd`).
    pub split: Option<Split>,
    /// Variant name; `None` to infer it from the files.
    pub variant: Option<String>,
    /// Soft masks have no background slot: put `1 - Σ m_k` in front.
    pub no_background: bool,
    /// Score missing predictions as all-background instead of failing.
    pub allow_missing: bool,
    /// Bootstrap resamples for the confidence intervals (0 to skip).
    pub bootstrap: usize,
    /// Seed of the bootstrap.
    pub seed: u64,
}

impl Options {
    /// Whether ground truth is centre-cropped and resized to 128x128.
    pub fn crops(&self) -> bool {
        self.protocol.crops() && !self.native_size
    }
}

impl Default for Options {
    fn default() -> Self {
        Options {
            protocol: Protocol::Clevrtex,
            metrics: Vec::new(),
            native_size: false,
            split: None,
            variant: None,
            no_background: false,
            allow_missing: false,
            bootstrap: 1000,
            seed: 0,
        }
    }
}

/// One object's contribution to the per-object breakdown.
#[derive(Clone, Debug, PartialEq)]
pub struct ObjectScore {
    /// `(kind, value)` pairs, e.g. `("material", "rope")`.
    pub groups: Vec<(&'static str, String)>,
    /// Matched IoU of the object's true slot.
    pub iou: f64,
    /// Best overlap of the object's true slot (largest f64 IoU over predicted segments).
    pub best_overlap: f64,
    /// Squared error summed over its pixels and channels, with a reconstruction.
    pub mse: Option<f64>,
}

/// The result for one image.
#[derive(Clone, Debug, PartialEq)]
pub struct ImageResult {
    /// Numeric index of the sample.
    pub index: u64,
    /// Stem of the sample.
    pub stem: String,
    /// Its metrics.
    pub scores: Scores,
    /// No prediction was found; scored as all-background.
    pub missing: bool,
    /// Objects (and the background, kind `ground_material`) for the breakdowns.
    pub objects: Vec<ObjectScore>,
    /// Metadata objects whose label does not occur in the (cropped) mask.
    pub objects_skipped: usize,
    /// Hash of the ground-truth files read.
    pub gt_hash: u64,
    /// Hash of the prediction files read (0 when missing).
    pub pred_hash: u64,
    /// What was wrong with the reconstruction, if anything.
    pub recon_issue: Option<ReconIssue>,
}

/// A reconstruction that is not plain values in [0, 1].
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum ReconIssue {
    /// NaN or infinite values (`nonfinite` of them), or errors too large to sum: its MSE (and
    /// its objects' squared errors) are undefined, left out of the means and counted.
    Undefined {
        /// Non-finite values (0 when the values are finite but their squared error is not).
        nonfinite: usize,
    },
    /// Finite values outside [0, 1]: scored as given (the benchmark does not clip), and
    /// warned about.
    OutOfRange {
        /// Smallest value.
        min: f32,
        /// Largest value.
        max: f32,
    },
}

/// Check float reconstruction values: non-finite, or outside [0, 1].
fn recon_issue(values: &[f32]) -> Option<ReconIssue> {
    let nonfinite = values.iter().filter(|v| !v.is_finite()).count();
    if nonfinite > 0 {
        return Some(ReconIssue::Undefined { nonfinite });
    }
    let (min, max) = values
        .iter()
        .fold((f32::INFINITY, f32::NEG_INFINITY), |(lo, hi), &v| {
            (lo.min(v), hi.max(v))
        });
    (min < 0.0 || max > 1.0).then_some(ReconIssue::OutOfRange { min, max })
}

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

const GT_HINT: &str = "the ground truth is damaged: regenerate or re-download this sample";

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

/// The size a ground-truth PNG declares in its header, checked before it is decoded: each side
/// at most the 4096 pixels any clevrtex image has (a 1 MB mask declaring 30000x30000 decoded
/// to 4.5 GB of labels).
/// The (width, height) in a ground-truth image's PNG header, if it can be read.
fn image_size(path: &Path) -> Option<(usize, usize)> {
    use std::io::Read;
    let mut head = Vec::with_capacity(64);
    std::fs::File::open(path)
        .ok()?
        .take(64)
        .read_to_end(&mut head)
        .ok()?;
    read::png_size_of_dataset_image(&head).ok()
}

fn gt_png_size(bytes: &[u8], path: &Path) -> Result<(usize, usize), EvalError> {
    read::png_size_of_dataset_image(bytes).map_err(|r| corrupt(path, r, GT_HINT))
}

fn score_sample(
    s: &crate::dataset::GtSample,
    files: &PredFiles,
    by_colour: bool,
    opts: &Options,
) -> Result<ImageResult, EvalError> {
    let mask_bytes = s.read(&s.mask, crate::dataset::MAX_FILE_BYTES)?;
    let meta_bytes = s.read(&s.meta, crate::dataset::MAX_METADATA_BYTES)?;
    gt_png_size(&mask_bytes, &s.mask)?;
    if let Some(problem) =
        clevrtex_dataset::dataset::png_mode_problem(&mask_bytes, clevrtex_scene::Pass::Mask)
    {
        return Err(corrupt(&s.mask, problem, GT_HINT));
    }
    let gt_mask = read::png_labels(&mask_bytes).map_err(|r| corrupt(&s.mask, r, GT_HINT))?;
    if let Some(&bad) = gt_mask.labels.iter().find(|&&l| l as usize >= MAX_SLOTS) {
        return Err(corrupt(
            &s.mask,
            format!("segment id `{bad}` is outside 0..{MAX_SLOTS}"),
            GT_HINT,
        ));
    }
    let sample_meta = meta::parse(&meta_bytes).map_err(|r| corrupt(&s.meta, r, GT_HINT))?;
    // Ids past the metadata's objects are no object anyone can name: refused as `verify`
    // refuses them, not scored.
    if let Some(n) = sample_meta.num_objects {
        if let Some(&bad) = gt_mask.labels.iter().find(|&&l| l as usize > n) {
            return Err(corrupt(
                &s.mask,
                format!(
                    "has id {bad} but its metadata `{}` has {n} objects (ids 0 to {n})",
                    s.meta.display()
                ),
                GT_HINT,
            ));
        }
    }
    let (gw, gh) = (gt_mask.width, gt_mask.height);
    let (truth, hw) = match opts.crops() {
        false => (gt_mask.labels, (gw, gh)),
        true => {
            let t = crop_resize_nearest(&gt_mask.labels, gw, gh, EVAL_SIDE).ok_or_else(|| {
                corrupt(
                    &s.mask,
                    format!("a {gw}x{gh} mask is too small to crop"),
                    GT_HINT,
                )
            })?;
            (t, (EVAL_SIDE, EVAL_SIDE))
        }
    };
    let n = hw.0 * hw.1;

    let mut gt_hasher_input = Vec::with_capacity(3);
    gt_hasher_input.push(xxh3_64(&mask_bytes));
    gt_hasher_input.push(xxh3_64(&meta_bytes));

    let (pred, pred_hash, missing) = if files.segmentation.is_some() {
        let (p, bytes) = predict::load(files, hw, opts.no_background).map_err(|e| {
            // A prediction of the image's size against a mask of another: the ground truth
            // is what disagrees with itself.
            match (&e, image_size(&s.image)) {
                (EvalError::ShapeMismatch { .. }, Some((w, h))) if (w, h) != (gw, gh) => corrupt(
                    &s.mask,
                    format!("the mask is {gw}x{gh} but its image is {w}x{h}"),
                    GT_HINT,
                ),
                _ => e,
            }
        })?;
        let hs: Vec<u8> = bytes
            .iter()
            .flat_map(|b| xxh3_64(b).to_le_bytes())
            .collect();
        (p, xxh3_64(&hs), false)
    } else {
        let p = predict::Prediction {
            labels: vec![0; n],
            slots: 1,
            recon: None,
        };
        (p, 0, true)
    };

    // The true image is needed only for MSE.
    let truth_rgb = match &pred.recon {
        Some(_) => {
            let img_bytes = s.read(&s.image, crate::dataset::MAX_FILE_BYTES)?;
            gt_hasher_input.push(xxh3_64(&img_bytes));
            gt_png_size(&img_bytes, &s.image)?;
            let img = read::png_rgb(&img_bytes).map_err(|r| corrupt(&s.image, r, GT_HINT))?;
            if (img.width, img.height) != (gw, gh) {
                return Err(corrupt(
                    &s.image,
                    format!(
                        "the image is {}x{} but its mask is {gw}x{gh}",
                        img.width, img.height
                    ),
                    GT_HINT,
                ));
            }
            Some(match opts.crops() {
                false => img.rgb,
                true => crop_resize_bilinear_rgb(&img.rgb, gw, gh, EVAL_SIDE)
                    .ok_or_else(|| corrupt(&s.image, "too small to crop", GT_HINT))?,
            })
        }
        None => None,
    };
    let recon = match (&truth_rgb, &pred.recon) {
        (Some(t), Some(p)) => Some(Recon {
            truth_rgb: t,
            pred_rgb: p.as_pred(),
        }),
        _ => None,
    };
    let mut recon_issue = match &pred.recon {
        Some(predict::ReconImage::Unit(v)) => recon_issue(v),
        _ => None,
    };
    let mut scores = score_image(&truth, &pred.labels, pred.slots, recon);
    let mse = Metric::Mse.index();
    if pred.recon.is_some() && scores.values[mse].is_none() {
        // Finite values whose squared error overflows (e.g. 1e30) are undefined too.
        if !matches!(recon_issue, Some(ReconIssue::Undefined { .. })) {
            recon_issue = Some(ReconIssue::Undefined { nonfinite: 0 });
        }
    }
    if let Some(ReconIssue::Undefined { .. }) = recon_issue {
        scores.values[mse] = None;
        scores.sq_err_per_true = None;
    }

    // Per-object breakdown: object i has label i + 1; the background goes by ground material.
    let mut objects = Vec::new();
    let mut skipped = 0;
    let mse_of = |t: usize| scores.sq_err_per_true.as_ref().map(|v| v[t]);
    if scores.true_sizes.first().is_some_and(|&s| s > 0) {
        if let Some(g) = &sample_meta.ground_material {
            objects.push(ObjectScore {
                groups: vec![("ground_material", g.clone())],
                iou: scores.iou_per_true[0],
                best_overlap: scores.best_overlap_per_true[0],
                mse: mse_of(0),
            });
        }
    }
    for (i, o) in sample_meta.objects.iter().enumerate() {
        let t = i + 1;
        if scores.true_sizes.get(t).is_none_or(|&s| s == 0) {
            skipped += 1;
            continue;
        }
        let mut groups = Vec::new();
        for (kind, v) in [
            ("material", &o.material),
            ("shape", &o.shape),
            ("size", &o.size),
        ] {
            if let Some(v) = v {
                groups.push((kind, v.clone()));
            }
        }
        if by_colour {
            if let Some(c) = &o.color {
                groups.push(("color", c.clone()));
            }
        }
        objects.push(ObjectScore {
            groups,
            iou: scores.iou_per_true[t],
            best_overlap: scores.best_overlap_per_true[t],
            mse: mse_of(t),
        });
    }
    let gh_bytes: Vec<u8> = gt_hasher_input
        .iter()
        .flat_map(|h| h.to_le_bytes())
        .collect();
    Ok(ImageResult {
        index: s.index,
        stem: s.stem.clone(),
        scores,
        missing,
        objects,
        objects_skipped: skipped,
        gt_hash: xxh3_64(&gh_bytes),
        pred_hash,
        recon_issue,
    })
}
