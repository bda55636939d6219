//! Means over scenes of each rung: the table, the summary against the original settings and
//! the error-against-time plot.

use std::collections::BTreeMap;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use clevrtex_scene::quality::{Quality, Sampling};

use crate::ladder::Setting;
use crate::measure::Row;
use crate::plot;

/// Means over scenes of one setting on one Blender.
pub struct Agg {
    blender: String,
    setting: Setting,
    scenes: usize,
    wall_s: f64,
    cycles_s: f64,
    /// CPU seconds of the render, all threads (NaN where the CSV lacks them).
    cycles_cpu_s: f64,
    rmse_linear: f64,
    rel_error: f64,
    bias: f64,
    psnr_srgb: f64,
    mask_equal: usize,
    depth_equal: usize,
}

/// One [`Agg`] per (Blender, rung), in the rows' order; a Blender given twice (runs
/// alternated against load drift) is one, its runs averaged.
pub fn aggregate(rows: &[Row]) -> Vec<Agg> {
    let mut order: Vec<(String, String)> = Vec::new();
    let mut by: BTreeMap<(String, String), Vec<&Row>> = BTreeMap::new();
    for r in rows {
        let key = (r.blender.clone(), r.setting.label.clone());
        if !by.contains_key(&key) {
            order.push(key.clone());
        }
        by.entry(key).or_default().push(r);
    }
    order
        .into_iter()
        .map(|key| {
            let rs = &by[&key];
            let k = rs.len() as f64;
            let m = |f: &dyn Fn(&Row) -> f64| rs.iter().map(|r| f(r)).sum::<f64>() / k;
            Agg {
                blender: key.0.clone(),
                setting: rs[0].setting.clone(),
                scenes: rs.len(),
                wall_s: m(&|r| r.wall_s),
                cycles_s: m(&|r| r.cycles_s),
                cycles_cpu_s: m(&|r| r.cycles_cpu_s),
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

/// The Blenders of `agg`, in order of appearance.
fn blenders(agg: &[Agg]) -> Vec<&str> {
    let mut v: Vec<&str> = Vec::new();
    for a in agg {
        if !v.contains(&a.blender.as_str()) {
            v.push(&a.blender);
        }
    }
    v
}

/// The table of means, one line per rung (per Blender, when several), with a legend.
pub fn table(agg: &[Agg]) -> String {
    let mut s = String::new();
    let several = blenders(agg).len() > 1;
    let _ = writeln!(
        s,
        "\n{}{:<30} {:>5} {:>6} {:>7} {:>5} {:>8} {:>8} {:>9} {:>8} {:>7} {:>6} {:>5} {:>5}",
        if several {
            format!("{:<10} ", "blender")
        } else {
            String::new()
        },
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
            "{}{:<30} {:>5} {:>6} {:>7} {:>5} {:>8.2} {:>8.2} {:>9.5} {:>8.4} {:>+7.4} {:>6.2} {:>5} {:>5}",
            if several { format!("{:<10} ", a.blender) } else { String::new() },
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

/// Per Blender: the rungs at most as noisy as the original settings, by wall time, and the
/// presets against the original (nothing without the `original-512` rung). Each Blender's
/// presets are measured against its own original and reference, so with several Blenders
/// this is the presets per version.
pub fn summary(agg: &[Agg]) -> String {
    let versions = blenders(agg);
    let mut s = String::new();
    for v in &versions {
        let mine: Vec<&Agg> = agg.iter().filter(|a| a.blender == *v).collect();
        let one = summary_of(&mine);
        if versions.len() > 1 && !one.is_empty() {
            let _ = write!(s, "\nBlender {v}:");
        }
        s.push_str(&one);
    }
    s
}

fn summary_of(agg: &[&Agg]) -> String {
    let mut s = against_original(agg);
    s.push_str(&fast_against_default(agg));
    s
}

/// The label of the 64-sample default's rung (`configs/base.json`'s samples, the original's
/// light paths).
pub const DEFAULT_RUNG: &str = "fixed-64";

/// The `fast` preset against the 64-sample default ([`DEFAULT_RUNG`]), by CPU seconds (Cycles'
/// time where a row lacks them), with its target: the default's error or less in at most half
/// its CPU time. Empty without both rungs.
fn fast_against_default(agg: &[&Agg]) -> String {
    let mut s = String::new();
    let fast = Quality::Fast.settings();
    let (Some(base), Some(f)) = (
        agg.iter().find(|a| a.setting.label == DEFAULT_RUNG),
        agg.iter().find(|a| a.setting.sampling == fast),
    ) else {
        return s;
    };
    let (cost, by) = if f.cycles_cpu_s > 0.0 && base.cycles_cpu_s > 0.0 {
        ((f.cycles_cpu_s, base.cycles_cpu_s), "CPU")
    } else {
        ((f.cycles_s, base.cycles_s), "Cycles")
    };
    let ratio = cost.0 / cost.1.max(1e-9);
    let ok = f.rel_error <= base.rel_error && ratio <= 0.5;
    let _ = writeln!(
        s,
        "preset fast (= {}) against {DEFAULT_RUNG} (the 64-sample default): {by} {:.2} s, x{ratio:.2} of its {:.2} s; rel error {:.4} vs {:.4}; bias {:+.4} (target: error <= {DEFAULT_RUNG}'s in <= 0.50 of its {by} time: {})",
        f.setting.label,
        cost.0,
        cost.1,
        f.rel_error,
        base.rel_error,
        f.bias,
        if ok { "met" } else { "NOT met" }
    );
    s
}

/// The rungs at most as noisy as the original, and the presets against it (nothing without
/// the `original-512` rung).
fn against_original(agg: &[&Agg]) -> String {
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
        .copied()
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
    let several = blenders(agg).len() > 1;
    let mut by: BTreeMap<String, Vec<(f64, f64)>> = BTreeMap::new();
    for a in agg {
        let key = if several {
            format!("{} {}", a.blender, a.setting.mode)
        } else {
            a.setting.mode.to_string()
        };
        by.entry(key).or_default().push((a.cycles_s, a.rel_error));
    }
    by.into_iter().collect()
}

/// One Blender's sums (then means) over its runs of one (rung, scene).
#[derive(Default, Clone, Copy)]
struct Cell {
    rel_error: f64,
    cycles_s: f64,
    cycles_cpu_s: f64,
    reference_mean: f64,
    runs: f64,
}

/// Several Blenders side by side (empty with one): for each rung and scene, each Blender's
/// error against its own reference, its Cycles time, the CPU time it needs to reach the first
/// Blender's error (`(err / first's err)^2 x cycles / first's cycles`: error falls as
/// 1/sqrt(samples) and time grows with samples) and its reference's mean linear value over
/// the first's (brightness). A Blender given more than once (runs alternated against load
/// drift) is averaged over its runs.
pub fn side_by_side(rows: &[Row]) -> String {
    let mut versions: Vec<&str> = Vec::new();
    let mut keys: Vec<(&str, &str)> = Vec::new();
    let mut sums: BTreeMap<(&str, &str, &str), Cell> = BTreeMap::new();
    for r in rows {
        if !versions.contains(&r.blender.as_str()) {
            versions.push(&r.blender);
        }
        let key = (r.setting.label.as_str(), r.scene.as_str());
        if !keys.contains(&key) {
            keys.push(key);
        }
        let e = sums.entry((key.0, key.1, &r.blender)).or_default();
        e.rel_error += r.errors.rel_error;
        e.cycles_s += r.cycles_s;
        e.cycles_cpu_s += r.cycles_cpu_s;
        e.reference_mean += r.reference_mean;
        e.runs += 1.0;
    }
    let mut s = String::new();
    if versions.len() < 2 {
        return s;
    }
    let cell = |rung: &str, scene: &str, v: &str| {
        sums.get(&(rung, scene, v)).map(|c| Cell {
            rel_error: c.rel_error / c.runs,
            cycles_s: c.cycles_s / c.runs,
            cycles_cpu_s: c.cycles_cpu_s / c.runs,
            reference_mean: c.reference_mean / c.runs,
            runs: c.runs,
        })
    };
    let first = versions[0];
    let _ = writeln!(
        s,
        "\nBlenders side by side (each against its own reference; ratios against {first}, the first given):\n{:<30} {:<10} {:<10} {:>8} {:>9} {:>9} {:>14} {:>10}",
        "setting", "scene", "blender", "rel err", "cycles s", "cpu s", "CPU to 1st err", "ref mean"
    );
    for &(rung, scene) in &keys {
        let Some(base) = cell(rung, scene, first) else {
            continue;
        };
        for v in &versions {
            let Some(c) = cell(rung, scene, v) else {
                continue;
            };
            // CPU seconds where both have them (this version's bridge), else Cycles' wall time.
            let cost = if c.cycles_cpu_s > 0.0 && base.cycles_cpu_s > 0.0 {
                c.cycles_cpu_s / base.cycles_cpu_s
            } else {
                c.cycles_s / base.cycles_s
            };
            let cpu = (c.rel_error / base.rel_error).powi(2) * cost;
            let _ = writeln!(
                s,
                "{rung:<30} {scene:<10} {v:<10} {:>8.4} {:>9.2} {:>9.2} {:>13.2}x {:>9.3}x",
                c.rel_error,
                c.cycles_s,
                c.cycles_cpu_s,
                cpu,
                c.reference_mean / base.reference_mean
            );
        }
    }
    s.push_str("(cpu s: CPU seconds of the Blender process during the render, all threads, NaN for rows of a CSV without it; CPU to 1st err: the CPU time this Blender needs for the first's error at this rung, (err / first's)^2 x cpu s / first's, by cycles s where cpu s is missing; ref mean: mean linear value of its reference over the first's, NaN for rows of a CSV without it)\n");
    s
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::metrics::Errors;

    fn row(blender: &str, scene: &str, rel_error: f64, cycles_s: f64, reference_mean: f64) -> Row {
        Row {
            blender: blender.into(),
            scene: scene.into(),
            variant: "full".into(),
            width: 16,
            height: 12,
            setting: crate::ladder::ladder(true).remove(0),
            wall_s: cycles_s + 1.0,
            cycles_s,
            cycles_cpu_s: f64::NAN,
            errors: Errors {
                rmse_linear: rel_error / 4.0,
                rel_error,
                bias: 0.0,
                psnr_srgb: 30.0,
                mask_equal: true,
                depth_equal: true,
            },
            reference_mean,
        }
    }

    #[test]
    fn blenders_are_aggregated_apart_and_put_side_by_side() {
        // 3.4, 4.5, 4.5, 3.4 alternated on one scene: each version's two runs are averaged.
        let rows = [
            row("3.4.1", "full#0", 0.2, 10.0, 0.5),
            row("4.5.15", "full#0", 0.3, 12.0, 0.49),
            row("4.5.15", "full#0", 0.5, 14.0, 0.49),
            row("3.4.1", "full#0", 0.2, 12.0, 0.5),
        ];
        let agg = aggregate(&rows);
        assert_eq!(agg.len(), 2);
        assert_eq!((agg[0].blender.as_str(), agg[0].scenes), ("3.4.1", 2));
        assert!((agg[1].rel_error - 0.4).abs() < 1e-12);
        assert!((agg[1].cycles_s - 13.0).abs() < 1e-12);
        let t = table(&agg);
        assert!(t.contains("blender") && t.contains("4.5.15"), "{t}");

        let s = side_by_side(&rows);
        // CPU time to 3.4's error: (0.4 / 0.2)^2 x 13 / 11 = 4.73; reference 0.49 / 0.5.
        let line = s
            .lines()
            .find(|l| l.contains("4.5.15"))
            .unwrap_or_else(|| panic!("{s}"));
        assert!(line.contains("4.73x") && line.contains("0.980x"), "{line}");
        assert!(s.contains("ratios against 3.4.1"), "{s}");
        // With CPU seconds on every row, the ratio is by them: (0.4 / 0.2)^2 x 30 / 20 = 6.00.
        let with_cpu: Vec<Row> = rows
            .iter()
            .map(|r| Row {
                cycles_cpu_s: if r.blender == "3.4.1" { 20.0 } else { 30.0 },
                ..r.clone()
            })
            .collect();
        let s = side_by_side(&with_cpu);
        let line = s.lines().find(|l| l.contains("4.5.15")).unwrap();
        assert!(line.contains("6.00x") && line.contains("30.00"), "{line}");
        // One Blender: nothing side by side, no Blender column.
        assert_eq!(side_by_side(&rows[..1]), "");
        assert!(!table(&aggregate(&rows[..1])).contains("blender"));
    }

    #[test]
    fn fast_is_judged_against_the_64_sample_default_by_cpu_time() {
        let fast = crate::ladder::lever_rungs(true)
            .into_iter()
            .find(|s| s.sampling == Quality::Fast.settings())
            .expect("a rung with the fast preset's settings");
        let default = crate::ladder::ladder(true)
            .into_iter()
            .find(|s| s.label == DEFAULT_RUNG)
            .unwrap();
        let at = |setting: &Setting, rel_error: f64, cpu: f64| Row {
            setting: setting.clone(),
            cycles_cpu_s: cpu,
            ..row("4.5.15", "full#0", rel_error, 5.0, 0.5)
        };
        let verdict = |rows: &[Row]| summary(&aggregate(rows));
        // Less error for 0.40 of the CPU: met (wall time equal, so CPU decides).
        let s = verdict(&[at(&default, 0.10, 10.0), at(&fast, 0.08, 4.0)]);
        assert!(
            s.contains("x0.40 of its 10.00 s") && s.contains(": met)"),
            "{s}"
        );
        // More error, or more than half the CPU: not met.
        let s = verdict(&[at(&default, 0.10, 10.0), at(&fast, 0.11, 4.0)]);
        assert!(s.contains("NOT met"), "{s}");
        let s = verdict(&[at(&default, 0.10, 10.0), at(&fast, 0.05, 6.0)]);
        assert!(s.contains("x0.60") && s.contains("NOT met"), "{s}");
        // Without the default's rung: no line.
        assert!(!verdict(&[at(&fast, 0.05, 4.0)]).contains("preset fast"));
    }
}
