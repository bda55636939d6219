//! Rendering a [`Report`] as a table, JSON and CSV.

use std::fmt::Write as _;

use serde_json::{json, Map, Value};

use crate::evaluate::Report;
use crate::metrics::Metric;

fn num(v: Option<f64>) -> Value {
    v.filter(|x| x.is_finite()).map_or(Value::Null, Value::from)
}

/// The JSON report: `metrics` (name -> number, `null` where no image defines it; the metrics
/// reported, by default the protocol's), `ci95`, `counts`, `breakdowns` and `provenance`.
pub fn to_json(r: &Report, tool_version: &str) -> Value {
    let mut metrics = Map::new();
    let mut ci = Map::new();
    let mut undefined = Map::new();
    for &m in &r.metrics {
        let s = r.summary(m);
        metrics.insert(m.name().into(), num(s.mean));
        ci.insert(
            m.name().into(),
            s.ci.map_or(Value::Null, |(a, b)| json!([a, b])),
        );
        undefined.insert(m.name().into(), json!(r.images.len() - s.defined));
    }
    let mut breakdowns = Map::new();
    for (kind, groups) in &r.breakdowns {
        let mut g = Map::new();
        for (name, grp) in groups {
            g.insert(
                name.clone(),
                json!({
                    "count": grp.count,
                    (Metric::MIoU.name()): grp.iou,
                    (Metric::Mse.name()): num(grp.mse),
                    (Metric::MBo.name()): grp.best_overlap,
                }),
            );
        }
        breakdowns.insert((*kind).into(), Value::Object(g));
    }
    json!({
        "metrics": metrics,
        "ci95": ci,
        "counts": {
            "images": r.images.len(),
            "missing": r.missing(),
            "undefined": undefined,
            "objects_skipped": r.objects_skipped(),
            "recon_undefined": r.recon_undefined(),
            "recon_out_of_range": r.recon_out_of_range(),
        },
        "breakdowns": breakdowns,
        "provenance": {
            "tool": "clevrtex",
            "version": tool_version,
            "variant": r.variant,
            "split": r.split.name(),
            "protocol": r.protocol.name(),
            "protocol_source": r.protocol.source(),
            "metrics": r.metrics.iter().map(|m| m.name()).collect::<Vec<_>>(),
            "crop_resize": r.cropped,
            "no_background": r.no_background,
            "bootstrap": r.bootstrap,
            "seed": r.seed,
            "first_index": r.images.first().map(|i| i.index),
            "last_index": r.images.last().map(|i| i.index),
            "gt_dir": r.gt_dir.display().to_string(),
            "preds_dir": r.pred_dir.display().to_string(),
            "gt_hash_xxh3": format!("{:016x}", r.gt_hash),
            "preds_hash_xxh3": format!("{:016x}", r.pred_hash),
        },
    })
}

/// One CSV row per image: index, stem, every metric (empty where undefined), segment counts,
/// `num_pairs` and whether the prediction was missing.
pub fn to_csv(r: &Report) -> String {
    let mut s = String::from("index,stem");
    for &m in &r.metrics {
        let _ = write!(s, ",{}", m.name());
    }
    s.push_str(",true_segments,pred_segments,num_pairs,missing\n");
    for img in &r.images {
        let _ = write!(s, "{},{}", img.index, img.stem);
        for &m in &r.metrics {
            match img.scores.get(m) {
                Some(v) if v.is_finite() => {
                    let _ = write!(s, ",{v}");
                }
                _ => s.push(','),
            }
        }
        let _ = writeln!(
            s,
            ",{},{},{},{}",
            img.scores.true_segments,
            img.scores.pred_segments,
            img.scores.num_pairs,
            u8::from(img.missing)
        );
    }
    s
}

/// The human-readable table for stdout.
pub fn to_table(r: &Report) -> String {
    let mut s = String::new();
    let _ = writeln!(
        s,
        "clevrtex eval: variant `{}`, split `{}` ({} images), protocol `{}`",
        r.variant,
        r.split.name(),
        r.images.len(),
        r.protocol.name()
    );
    let _ = writeln!(
        s,
        "protocol `{}`: definitions of {}; ground truth {}",
        r.protocol.name(),
        r.protocol.source(),
        if r.cropped {
            "centre-cropped and resized to 128x128"
        } else {
            "at its own size"
        }
    );
    let ci_head = if r.bootstrap > 0 {
        "95% CI (bootstrap)"
    } else {
        ""
    };
    let _ = writeln!(
        s,
        "\n{:<11} {:>10}  {:<24} {:>7}",
        "metric", "value", ci_head, "images"
    );
    for &m in &r.metrics {
        let sm = r.summary(m);
        let value = sm.mean.map_or("n/a".to_string(), |v| fmt_val(m, v));
        let ci = sm.ci.map_or(String::new(), |(a, b)| {
            format!("[{}, {}]", fmt_val(m, a), fmt_val(m, b))
        });
        let _ = writeln!(
            s,
            "{:<11} {:>10}  {:<24} {:>7}",
            m.name(),
            value,
            ci,
            sm.defined
        );
    }
    if r.metrics.contains(&Metric::Mse) && r.summary(Metric::Mse).mean.is_none() {
        s.push_str(
            "\nMSE: no reconstructions given (`<stem>_recon.png` or `recon` in the `.npz`)\n",
        );
    }
    let missing = r.missing();
    if missing > 0 {
        let _ = writeln!(
            s,
            "\n{missing} predictions missing, scored as all-background (`--allow-missing`)"
        );
    }
    for (kind, groups) in &r.breakdowns {
        let _ = writeln!(
            s,
            "\n{:<30} {:>6} {:>8} {:>8} {:>10}",
            format!("by {kind}"),
            "count",
            Metric::MIoU.name(),
            Metric::MBo.name(),
            Metric::Mse.name()
        );
        for (name, g) in groups {
            let mse = g.mse.map_or("n/a".to_string(), |v| format!("{v:.3}"));
            let _ = writeln!(
                s,
                "  {:<28} {:>6} {:>8.4} {:>8.4} {:>10}",
                // A material or shape name from the (untrusted) metadata: escaped.
                clevrtex_scene::text::printable(name),
                g.count,
                g.iou,
                g.best_overlap,
                mse
            );
        }
    }
    let skipped = r.objects_skipped();
    if skipped > 0 {
        let _ = writeln!(
            s,
            "\n{skipped} objects not visible after cropping were left out of the breakdowns"
        );
    }
    s
}

fn fmt_val(m: Metric, v: f64) -> String {
    format!("{v:.*}", m.spec().decimals)
}

/// The warnings of a run for stderr: reconstructions with undefined MSE or out-of-range
/// values, predictions missing.
pub fn warnings(r: &Report) -> Vec<String> {
    let n = r.images.len();
    let mut out = Vec::new();
    let undefined = r.recon_undefined();
    if undefined > 0 {
        out.push(format!("warning: {undefined} of {n} reconstructions hold NaN or infinite values (or errors too large to sum): their MSE is undefined and left out of the mean (`recon_undefined` in the JSON)"));
    }
    let out_of_range = r.recon_out_of_range();
    if out_of_range > 0 {
        out.push(format!("warning: {out_of_range} of {n} reconstructions hold values outside [0, 1]; they are scored as given, not clipped (`recon_out_of_range` in the JSON)"));
    }
    let missing = r.missing();
    if missing > 0 {
        out.push(format!(
            "warning: {missing} of {n} predictions were missing and scored as all-background"
        ));
    }
    out
}
