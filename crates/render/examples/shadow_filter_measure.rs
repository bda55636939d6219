//! RMSE of the shadow pass (`clevrtex_render::post::filter_shadow`, the shipped filter and
//! variants) against the 256-spp reference, on the EXRs that
//! `blender_scripts/dev/shadow_measure.py` leaves in its `--out` folder (white methods are
//! saved as `white-paired-N_{lit,un}.exr`; dev only; numbers in `docs/performance.md`,
//! "Shadow pass"):
//!
//! ```text
//! cargo run --release -p clevrtex-render --example shadow_filter_measure -- \
//!     OUT white-paired-16 [white-paired-8 ...]
//! ```
//!
//! For every scene folder of OUT (the one named `open_floor` is reported as its maximum) and
//! every method given, it prints the RMSE of the 8-bit pass (as published) for: no filter,
//! the shipped filter, and variants (radius, tolerance, range, ratio of sums or mean of
//! ratios), each against the unfiltered `white-paired-256` pair (the reference, another
//! seed), with the pass's own rule for undefined pixels. Where the second reference
//! (`ref2-white-paired-256`, `--second-ref`) is there, the first line is the two
//! references' RMSE: the reference's own noise, part of every number. The instance ids come
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
            let (rl, ru) = (
                lum(&read("white-paired-256_lit.exr")),
                lum(&read("white-paired-256_un.exr")),
            );
            let reference = quantised(&post::filter_shadow(&rl, &ru, &ids, w, variants[0].1));
            if d.join("ref2-white-paired-256_un.exr").exists() {
                let (l2, u2) = (
                    lum(&read("ref2-white-paired-256_lit.exr")),
                    lum(&read("ref2-white-paired-256_un.exr")),
                );
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
            let (l, u) = (
                lum(&read(&format!("{method}_lit.exr"))),
                lum(&read(&format!("{method}_un.exr"))),
            );
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
