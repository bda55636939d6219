//! The bench's rows as CSV (`OUT/bench-render.csv`), and back (`--plot-only`).

use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use anyhow::{bail, Context};
use clevrtex_scene::quality::Sampling;

use crate::ladder::{self, Setting};
use crate::measure::Row;
use crate::metrics::Errors;

/// The columns before `blender` was added: CSVs of older versions still load (their rows'
/// Blender is unknown, empty).
const CSV_HEADER_V1: &str = "scene,variant,setting,mode,width,height,samples,adaptive_threshold,max_bounces,diffuse_bounces,glossy_bounces,transmission_bounces,transparent_max_bounces,clamp_indirect,wall_s,cycles_s,rmse_linear,rel_error,bias,psnr_srgb,mask_equal,depth_equal";
/// The columns before `cycles_cpu_s` was added (its rows' CPU time is unknown, NaN).
const CSV_HEADER_V2: &str = "scene,variant,setting,mode,width,height,samples,adaptive_threshold,max_bounces,diffuse_bounces,glossy_bounces,transmission_bounces,transparent_max_bounces,clamp_indirect,wall_s,cycles_s,rmse_linear,rel_error,bias,psnr_srgb,mask_equal,depth_equal,blender,reference_mean";
const CSV_HEADER: &str = "scene,variant,setting,mode,width,height,samples,adaptive_threshold,max_bounces,diffuse_bounces,glossy_bounces,transmission_bounces,transparent_max_bounces,clamp_indirect,wall_s,cycles_s,rmse_linear,rel_error,bias,psnr_srgb,mask_equal,depth_equal,blender,reference_mean,cycles_cpu_s";

/// The CSV of a bench run with output folder `out`.
pub fn path(out: &Path) -> PathBuf {
    out.join("bench-render.csv")
}

/// Write `rows` to [`path`]`(out)`.
pub fn save(rows: &[Row], out: &Path) -> anyhow::Result<()> {
    let csv = path(out);
    clevrtex_dataset::atomic::write(&csv, to_csv(rows).as_bytes())
        .with_context(|| format!("cannot write `{}`", csv.display()))
}

/// The rows of an earlier run with output folder `out`.
pub fn load(out: &Path) -> anyhow::Result<Vec<Row>> {
    let csv = path(out);
    let text = std::fs::read_to_string(&csv).with_context(|| {
        format!(
            "cannot read `{}`\nhint: run `clevrtex bench render --out {}` first",
            csv.display(),
            out.display()
        )
    })?;
    from_csv(&text).with_context(|| format!("bad CSV `{}`", csv.display()))
}

/// The CSV text of `rows`.
pub fn to_csv(rows: &[Row]) -> String {
    let mut s = format!("{CSV_HEADER}\n");
    for r in rows {
        let p = &r.setting.sampling;
        let _ = writeln!(
            s,
            "{},{},{},{},{},{},{},{},{},{},{},{},{},{},{:.4},{:.4},{:.6},{:.6},{:.6},{},{},{},{},{:.6},{:.4}",
            r.scene,
            r.variant,
            r.setting.label,
            r.setting.mode,
            r.width,
            r.height,
            p.samples,
            p.adaptive_threshold
                .map_or(String::new(), |t| t.to_string()),
            p.max_bounces,
            p.diffuse_bounces,
            p.glossy_bounces,
            p.transmission_bounces,
            p.transparent_max_bounces,
            p.clamp_indirect,
            r.wall_s,
            r.cycles_s,
            r.errors.rmse_linear,
            r.errors.rel_error,
            r.errors.bias,
            if r.errors.psnr_srgb.is_finite() {
                format!("{:.3}", r.errors.psnr_srgb)
            } else {
                "inf".to_string()
            },
            r.errors.mask_equal,
            r.errors.depth_equal,
            r.blender.replace(',', " "),
            r.reference_mean,
            r.cycles_cpu_s,
        );
    }
    s
}

/// Rows back from [`to_csv`]'s output.
pub fn from_csv(text: &str) -> anyhow::Result<Vec<Row>> {
    let mut lines = text.lines();
    let cells = match lines.next() {
        Some(CSV_HEADER) => 25,
        Some(CSV_HEADER_V2) => 24,
        Some(CSV_HEADER_V1) => 22,
        _ => bail!("unexpected header\nhint: the CSV must come from `clevrtex bench render`"),
    };
    lines
        .enumerate()
        .map(|(i, line)| {
            let c: Vec<&str> = line.split(',').collect();
            if c.len() != cells {
                bail!("line {}: {} cells, expected {cells}", i + 2, c.len());
            }
            let f = |k: usize| -> anyhow::Result<f64> {
                if c[k] == "inf" {
                    return Ok(f64::INFINITY);
                }
                c[k].parse()
                    .with_context(|| format!("line {}: bad number `{}`", i + 2, c[k]))
            };
            let u = |k: usize| f(k).map(|v| v as u32);
            let mode = [
                "fixed",
                "adaptive",
                "adaptive-lowbounce",
                "adaptive-clamp",
                "preset",
                "notree",
                "guiding",
                "bluenoise",
                "oidn",
                "oidn-notree",
            ]
            .into_iter()
            .find(|m| *m == c[3])
            .unwrap_or("other");
            Ok(Row {
                blender: c.get(22).map_or(String::new(), |v| v.to_string()),
                scene: c[0].to_string(),
                variant: c[1].to_string(),
                width: u(4)?,
                height: u(5)?,
                setting: Setting {
                    mode,
                    label: c[2].to_string(),
                    sampling: Sampling {
                        samples: u(6)?,
                        adaptive_threshold: if c[7].is_empty() {
                            None
                        } else {
                            Some(f(7)? as f32)
                        },
                        max_bounces: u(8)?,
                        diffuse_bounces: u(9)?,
                        glossy_bounces: u(10)?,
                        transmission_bounces: u(11)?,
                        transparent_max_bounces: u(12)?,
                        clamp_indirect: f(13)? as f32,
                        // Not in the CSV: the lever rungs are known by their labels.
                        levers: ladder::lever_rungs(false)
                            .into_iter()
                            .chain(ladder::lever_rungs(true))
                            .find(|s| s.label == c[2])
                            .map_or(clevrtex_scene::quality::Levers::NONE, |s| s.sampling.levers),
                    },
                },
                wall_s: f(14)?,
                cycles_s: f(15)?,
                errors: Errors {
                    rmse_linear: f(16)?,
                    rel_error: f(17)?,
                    bias: f(18)?,
                    psnr_srgb: f(19)?,
                    mask_equal: c[20] == "true",
                    depth_equal: c[21] == "true",
                },
                reference_mean: if cells >= 24 { f(23)? } else { f64::NAN },
                cycles_cpu_s: if cells >= 25 { f(24)? } else { f64::NAN },
            })
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn csv_round_trips() {
        let s = ladder::ladder(true).remove(5);
        let row = Row {
            blender: "4.5.15".into(),
            scene: "full#0".into(),
            variant: "full".into(),
            width: 160,
            height: 120,
            setting: s.clone(),
            wall_s: 1.5,
            cycles_s: 1.25,
            cycles_cpu_s: 2.5,
            errors: Errors {
                rmse_linear: 0.125,
                rel_error: 0.5,
                bias: -0.25,
                psnr_srgb: f64::INFINITY,
                mask_equal: true,
                depth_equal: false,
            },
            reference_mean: 0.375,
        };
        let text = to_csv(std::slice::from_ref(&row));
        let back = from_csv(&text).unwrap();
        assert_eq!(back.len(), 1);
        let b = &back[0];
        assert_eq!(b.setting, s);
        assert_eq!(
            (b.width, b.height, b.wall_s, b.cycles_s),
            (160, 120, 1.5, 1.25)
        );
        assert_eq!(b.errors, row.errors);
        assert_eq!((b.blender.as_str(), b.reference_mean), ("4.5.15", 0.375));
        assert_eq!(b.cycles_cpu_s, 2.5);
        assert_eq!(to_csv(&back), text);
        // A CSV of the version before the CPU column still loads, CPU time unknown.
        let v2: String = text
            .lines()
            .map(|l| l.rsplit_once(',').unwrap().0.to_string() + "\n")
            .collect();
        assert!(v2.starts_with(CSV_HEADER_V2), "{v2}");
        let back = from_csv(&v2).unwrap();
        assert_eq!(
            (back[0].blender.as_str(), back[0].reference_mean),
            ("4.5.15", 0.375)
        );
        assert!(back[0].cycles_cpu_s.is_nan());
        // A CSV of the version before the Blender column still loads, Blender unknown.
        let old: String = text
            .lines()
            .map(|l| l.rsplitn(4, ',').nth(3).unwrap().to_string() + "\n")
            .collect();
        assert!(old.starts_with(CSV_HEADER_V1), "{old}");
        let back = from_csv(&old).unwrap();
        assert_eq!(back[0].blender, "");
        assert!(back[0].reference_mean.is_nan());
        assert_eq!(back[0].errors, row.errors);
        assert!(from_csv("nope\n")
            .unwrap_err()
            .to_string()
            .contains("hint:"));
    }
}
