//! One image scored: its ground truth read and checked, its prediction loaded, its metrics and
//! the per-object breakdown.

use std::path::Path;

use xxhash_rust::xxh3::xxh3_64;

use crate::dataset::PredFiles;
use crate::error::{corrupt, EvalError, MAX_SLOTS};
use crate::metrics::{score_image, Metric, Recon, Scores};
use crate::protocol::Options;
use crate::resize::{crop_resize_bilinear_rgb, crop_resize_nearest, EVAL_SIDE};
use crate::{meta, predict, read};

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

const GT_HINT: &str = "the ground truth is damaged: regenerate or re-download this sample";

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

/// The size a ground-truth PNG declares in its header, checked before it is decoded: each side
/// at most the 4096 pixels any clevrtex image has (a 1 MB mask declaring 30000x30000 decoded
/// to 4.5 GB of labels).
fn gt_png_size(bytes: &[u8], path: &Path) -> Result<(usize, usize), EvalError> {
    read::png_size_of_dataset_image(bytes).map_err(|r| corrupt(path, r, GT_HINT))
}

pub(crate) fn score_sample(
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
