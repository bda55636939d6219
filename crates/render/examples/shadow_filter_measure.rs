//! RMSE of the shadow pass (`clevrtex_render::post::filter_shadow`, the shipped filter and
//! variants) against the 256-spp reference, on the EXRs that
//! `blender_scripts/dev/shadow_measure.py` leaves in its `--out` folder (white methods are
//! saved as `white-single-N.exr`, one render, or `white-paired-N_{lit,un}.exr`, a pair; dev
//! only; numbers in `docs/notes/performance.md`, "Shadow pass"):
//!
//! ```text
//! cargo run --release -p clevrtex-render --example shadow_filter_measure -- \
//!     OUT white-single-24 [white-single-16 ...]
//! ```
//!
//! For every scene folder of OUT (the one named `open_floor` is reported as its maximum) and
//! every method given, it prints the RMSE of the 8-bit pass (as published) for: no filter,
//! the shipped filter, and variants (radius, tolerance, range, ratio of sums or mean of
//! ratios), each against the unfiltered `white-single-256` render (or `white-paired-256`
//! pair: the reference, another seed), with the pass's own rule for undefined pixels. Where
//! the second reference (`ref2-white-single-256`, `--second-ref`) is there, the first line
//! is the two references' RMSE: the reference's own noise, part of every number. The instance ids come
//! from `final.exr` (its `IndexOB` pass). With `SPLIT=1` in the environment it also prints,
//! on stderr, each variant's RMSE on the floor (id 0) and on the objects.

use std::path::Path;

use clevrtex_render::exr_io::Channels;
use clevrtex_render::post::{self, ShadowFilter, SHADOW_FILTER};

fn lum(ch: &Channels) -> Vec<f32> {
    let get = |c: &str| {
        ch.get(&format!("ViewLayer.DiffDir.{c}"))
            .expect("DiffDir pass")
    };
    let (r, g, b) = (get("R"), get("G"), get("B"));
    (0..r.len())
        .map(|i| 0.2126 * r[i] + 0.7152 * g[i] + 0.0722 * b[i])
        .collect()
}

/// The light with and without object shadows of method `name` in scene folder `d`: one
/// render `name.exr` (green with, red without: `builder.OneRenderShadow`) or the pair
/// `name_lit.exr` / `name_un.exr` (luminance of `DiffDir`).
fn lit_un(d: &Path, name: &str) -> (Vec<f32>, Vec<f32>) {
    let read = |n: &str| Channels::read(&d.join(n)).expect("EXR");
    let single = d.join(format!("{name}.exr"));
    if single.exists() {
        let ch = read(&format!("{name}.exr"));
        let get = |c: &str| {
            ch.get(&format!("ViewLayer.DiffDir.{c}"))
                .expect("DiffDir pass")
                .to_vec()
        };
        return (get("G"), get("R"));
    }
    (
        lum(&read(&format!("{name}_lit.exr"))),
        lum(&read(&format!("{name}_un.exr"))),
    )
}

/// The reference's method in `d`: one render per reference now, the pair before.
fn reference_method(d: &Path, prefix: &str) -> Option<String> {
    ["white-single-256", "white-paired-256"]
        .iter()
        .map(|m| format!("{prefix}{m}"))
        .find(|m| d.join(format!("{m}.exr")).exists() || d.join(format!("{m}_un.exr")).exists())
}

fn quantised(s: &[Option<f32>]) -> Vec<f32> {
    s.iter()
        .map(|v| v.map_or(0.0, |v| (v.clamp(0.0, 1.0) * 255.0).round() / 255.0))
        .collect()
}

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let Some((out, methods)) = args.split_first() else {
        eprintln!("usage: shadow_filter_measure OUT METHOD [METHOD ...]");
        std::process::exit(2);
    };
    let mut variants: Vec<(String, ShadowFilter)> = vec![(
        "none".into(),
        ShadowFilter {
            radius: 0,
            ..SHADOW_FILTER
        },
    )];
    variants.push(("shipped".into(), SHADOW_FILTER));
    for radius in [1, 2, 3] {
        for tolerance in [0.1, 0.25, f32::INFINITY] {
            for range in [0.1, 0.2, 0.3, f32::INFINITY] {
                for ratio_of_sums in [true, false] {
                    let f = ShadowFilter {
                        radius,
                        tolerance,
                        range,
                        ratio_of_sums,
                    };
                    let kind = if ratio_of_sums { "sums" } else { "ratios" };
                    variants.push((format!("r{radius} tol{tolerance} range{range} {kind}"), f));
                }
            }
        }
    }
    let mut dirs: Vec<_> = std::fs::read_dir(out)
        .expect("OUT folder")
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.join("final.exr").exists())
        .collect();
    dirs.sort();
    for method in methods {
        println!("## {method}");
        let mut table: Vec<Vec<f32>> = vec![Vec::new(); variants.len()];
        let mut names = Vec::new();
        for d in &dirs {
            let read = |n: &str| Channels::read(&d.join(n)).expect("EXR");
            let fin = read("final.exr");
            let ids: Vec<u8> = fin
                .get("ViewLayer.IndexOB.X")
                .expect("IndexOB pass")
                .iter()
                .map(|v| v.round() as u8)
                .collect();
            let w = fin.width;
            let (rl, ru) = lit_un(d, &reference_method(d, "").expect("a 256-spp reference"));
            let reference = quantised(&post::filter_shadow(&rl, &ru, &ids, w, variants[0].1));
            if let Some(ref2) = reference_method(d, "ref2-") {
                let (l2, u2) = lit_un(d, &ref2);
                let r2 = quantised(&post::filter_shadow(&l2, &u2, &ids, w, variants[0].1));
                let se: f32 = r2
                    .iter()
                    .zip(&reference)
                    .map(|(a, b)| (a - b).powi(2))
                    .sum();
                println!(
                    "{}: reference vs second reference {:.4}",
                    d.display(),
                    (se / r2.len() as f32).sqrt()
                );
            }
            let (l, u) = lit_un(d, method);
            let floor = d.file_name().is_some_and(|n| n == "open_floor");
            names.push(
                Path::new(d)
                    .file_name()
                    .unwrap()
                    .to_string_lossy()
                    .into_owned(),
            );
            for (k, (_, f)) in variants.iter().enumerate() {
                let s = quantised(&post::filter_shadow(&l, &u, &ids, w, *f));
                table[k].push(match floor {
                    true => s.iter().fold(0.0f32, |a, &b| a.max(b)),
                    false => {
                        let se: f32 = s.iter().zip(&reference).map(|(a, b)| (a - b).powi(2)).sum();
                        let part = |floor: bool| {
                            let (mut e, mut n) = (0.0f32, 0usize);
                            for i in 0..s.len() {
                                if (ids[i] == 0) == floor {
                                    e += (s[i] - reference[i]).powi(2);
                                    n += 1;
                                }
                            }
                            (e / n.max(1) as f32).sqrt()
                        };
                        if std::env::var_os("SPLIT").is_some() {
                            eprintln!(
                                "{} {:?}: floor {:.4} objects {:.4}",
                                names.last().unwrap(),
                                f,
                                part(true),
                                part(false)
                            );
                        }
                        (se / s.len() as f32).sqrt()
                    }
                });
            }
        }
        println!(
            "{:<36} {}   (open_floor: max)",
            "filter",
            names.iter().map(|n| format!("{n:>22}")).collect::<String>()
        );
        for (k, (name, _)) in variants.iter().enumerate() {
            let row: String = table[k].iter().map(|v| format!("{v:>22.4}")).collect();
            // Mean and worst over the scenes, open floor left out.
            let scenes: Vec<f32> = table[k]
                .iter()
                .zip(&names)
                .filter(|(_, n)| n.as_str() != "open_floor")
                .map(|(v, _)| *v)
                .collect();
            let mean = scenes.iter().sum::<f32>() / scenes.len().max(1) as f32;
            let worst = scenes.iter().fold(0.0f32, |a, &b| a.max(b));
            println!("{name:<36} {row}   mean {mean:.4} worst {worst:.4}");
        }
    }
}
