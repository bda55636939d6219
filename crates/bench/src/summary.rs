//! Means over scenes of each rung: the table, the summary against the original settings and
//! the error-against-time plot.

use std::collections::BTreeMap;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use clevrtex_scene::quality::{Quality, Sampling};

use crate::ladder::Setting;
use crate::measure::Row;
use crate::plot;

/// Means over scenes of one setting.
pub struct Agg {
    setting: Setting,
    scenes: usize,
    wall_s: f64,
    cycles_s: f64,
    rmse_linear: f64,
    rel_error: f64,
    bias: f64,
    psnr_srgb: f64,
    mask_equal: usize,
    depth_equal: usize,
}

/// One [`Agg`] per rung, in the rows' order.
pub fn aggregate(rows: &[Row]) -> Vec<Agg> {
    let mut order: Vec<String> = Vec::new();
    let mut by: BTreeMap<String, Vec<&Row>> = BTreeMap::new();
    for r in rows {
        if !by.contains_key(&r.setting.label) {
            order.push(r.setting.label.clone());
        }
        by.entry(r.setting.label.clone()).or_default().push(r);
    }
    order
        .into_iter()
        .map(|label| {
            let rs = &by[&label];
            let k = rs.len() as f64;
            let m = |f: &dyn Fn(&Row) -> f64| rs.iter().map(|r| f(r)).sum::<f64>() / k;
            Agg {
                setting: rs[0].setting.clone(),
                scenes: rs.len(),
                wall_s: m(&|r| r.wall_s),
                cycles_s: m(&|r| r.cycles_s),
                rmse_linear: m(&|r| r.errors.rmse_linear),
                rel_error: m(&|r| r.errors.rel_error),
                bias: m(&|r| r.errors.bias),
                // Mean of PSNR in dB; an identical image (infinite PSNR) would swamp it, so
                // it counts as 99 dB.
                psnr_srgb: m(&|r| r.errors.psnr_srgb.min(99.0)),
                mask_equal: rs.iter().filter(|r| r.errors.mask_equal).count(),
                depth_equal: rs.iter().filter(|r| r.errors.depth_equal).count(),
            }
        })
        .collect()
}

fn threshold_text(s: &Sampling) -> String {
    s.adaptive_threshold
        .map_or_else(|| "-".to_string(), |t| t.to_string())
}

/// The table of means, one line per rung, with a legend.
pub fn table(agg: &[Agg]) -> String {
    let mut s = String::new();
    let _ = writeln!(
        s,
        "\n{:<30} {:>5} {:>6} {:>7} {:>5} {:>8} {:>8} {:>9} {:>8} {:>7} {:>6} {:>5} {:>5}",
        "setting",
        "spp",
        "thresh",
        "bounce",
        "clamp",
        "wall s",
        "cycles s",
        "rmse lin",
        "rel err",
        "bias",
        "psnr",
        "mask",
        "depth"
    );
    for a in agg {
        let p = &a.setting.sampling;
        let _ = writeln!(
            s,
            "{:<30} {:>5} {:>6} {:>7} {:>5} {:>8.2} {:>8.2} {:>9.5} {:>8.4} {:>+7.4} {:>6.2} {:>5} {:>5}",
            a.setting.label,
            p.samples,
            threshold_text(p),
            format!("{}/{}/{}", p.max_bounces, p.diffuse_bounces, p.glossy_bounces),
            p.clamp_indirect,
            a.wall_s,
            a.cycles_s,
            a.rmse_linear,
            a.rel_error,
            a.bias,
            a.psnr_srgb,
            format!("{}/{}", a.mask_equal, a.scenes),
            format!("{}/{}", a.depth_equal, a.scenes),
        );
    }
    s.push_str("(means over scenes; bounce = max/diffuse/glossy; rel err = RMSE / mean of the reference, linear light; bias = relative difference of the means; psnr in dB on the 8-bit sRGB PNG; mask/depth = scenes whose pass equals that of a 1-sample render at the same seed exactly; references use another Cycles seed)\n");
    s
}

/// The rungs at most as noisy as the original settings, by wall time, and the presets against
/// the original (empty without the `original-512` rung).
pub fn summary(agg: &[Agg]) -> String {
    let mut s = String::new();
    let Some(orig) = agg.iter().find(|a| a.setting.label == "original-512") else {
        return s;
    };
    let _ = writeln!(
        s,
        "\noriginal (512 fixed samples, its bounces): rel error {:.4}, wall {:.2} s, cycles {:.2} s per image",
        orig.rel_error, orig.wall_s, orig.cycles_s
    );
    let _ = writeln!(
        s,
        "settings at most as noisy as the original (rel error <= original's), by wall time:"
    );
    let mut better: Vec<&Agg> = agg
        .iter()
        .filter(|a| a.setting.label != orig.setting.label && a.rel_error <= orig.rel_error)
        .collect();
    better.sort_by(|a, b| a.wall_s.total_cmp(&b.wall_s));
    if better.is_empty() {
        let _ = writeln!(s, "  (none)");
    }
    for a in better {
        let _ = writeln!(
            s,
            "  {:<30} wall x{:.2} of the original, rel error {:.4}, bias {:+.4}",
            a.setting.label,
            a.wall_s / orig.wall_s.max(1e-9),
            a.rel_error,
            a.bias
        );
    }
    for q in Quality::ALL {
        let Some(a) = agg.iter().find(|a| a.setting.sampling == q.settings()) else {
            continue;
        };
        let ratio = a.wall_s / orig.wall_s.max(1e-9);
        let _ = write!(
            s,
            "preset {q} (= {}): wall {:.2} s, x{ratio:.2} of the original; rel error {:.4} vs {:.4}; bias {:+.4}",
            a.setting.label, a.wall_s, a.rel_error, orig.rel_error, a.bias
        );
        if q == Quality::Standard {
            let ok = a.rel_error <= orig.rel_error && ratio <= 0.5;
            let _ = write!(
                s,
                " (target: error <= original's in <= 0.50 of its time: {})",
                if ok { "met" } else { "NOT met" }
            );
        }
        s.push('\n');
    }
    s
}

fn curves(agg: &[Agg]) -> Vec<plot::Curve> {
    let mut by: BTreeMap<&str, Vec<(f64, f64)>> = BTreeMap::new();
    for a in agg {
        by.entry(a.setting.mode)
            .or_default()
            .push((a.cycles_s, a.rel_error));
    }
    by.into_iter().map(|(k, v)| (k.to_string(), v)).collect()
}

/// The plot's file stem in output folder `out` (`.png` and `.svg` are written).
pub fn plot_stem(out: &Path) -> PathBuf {
    out.join("bench-render")
}

/// Draw the error-against-time plot of `agg` (`n` scenes at `width` x `height`) to
/// [`plot_stem`]`(out)`, with text if `text` (a font is registered). Returns `text`.
pub fn write_plot(
    agg: &[Agg],
    n: usize,
    width: u32,
    height: u32,
    out: &Path,
    text: bool,
) -> anyhow::Result<bool> {
    plot::write(
        &plot_stem(out),
        &format!("relative RMSE (linear) vs Cycles time, {n} scene(s) at {width}x{height}"),
        "Cycles render time per image (s)",
        "relative RMSE vs reference",
        &curves(agg),
        text,
    )
}
