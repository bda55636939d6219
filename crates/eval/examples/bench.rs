//! Time `evaluate` against decoding the same PNGs alone (the floor any evaluator pays).
//!
//! ```text
//! cargo run --release -p clevrtex-eval --example make_bench -- /tmp/evalbench 10000
//! cargo run --release -p clevrtex-eval --example bench -- /tmp/evalbench
//! ```
//! Both passes use rayon over images with the same thread pool; each is run twice and the
//! faster run is kept, so the page cache is warm for both.

use std::path::Path;
use std::time::Instant;

use clevrtex_eval::{dataset, evaluate, read, Options, Split};
use rayon::prelude::*;

fn decode_only(root: &Path) -> usize {
    let (_, samples) = dataset::discover_gt(&root.join("gt"), None).expect("ground truth");
    let preds = dataset::index_preds(&root.join("preds"), "full").expect("predictions");
    samples
        .par_iter()
        .map(|s| {
            let img = read::png_rgb(&std::fs::read(&s.image).unwrap()).unwrap();
            let mask = read::png_labels(&std::fs::read(&s.mask).unwrap()).unwrap();
            let p = &preds[&s.stem];
            let pm = read::png_labels(&std::fs::read(p.segmentation.as_ref().unwrap()).unwrap())
                .unwrap();
            let pr = read::png_rgb(&std::fs::read(p.recon.as_ref().unwrap()).unwrap()).unwrap();
            img.rgb.len() + mask.labels.len() + pm.labels.len() + pr.rgb.len()
        })
        .count()
}

/// CPU seconds (user + system) used by this process so far, from `/proc/self/stat` (Linux).
/// On a shared machine wall time depends on the other jobs; CPU time much less.
fn cpu_seconds() -> f64 {
    let stat = std::fs::read_to_string("/proc/self/stat").unwrap_or_default();
    let after = stat.rsplit_once(')').map_or("", |(_, rest)| rest);
    let f: Vec<f64> = after
        .split_whitespace()
        .map(|x| x.parse().unwrap_or(0.0))
        .collect();
    // Fields 14 and 15 (utime, stime) are at 11 and 12 after the command name; 100 ticks/s.
    (f.get(11).copied().unwrap_or(0.0) + f.get(12).copied().unwrap_or(0.0)) / 100.0
}

/// Best wall time and best CPU time over `runs`.
fn best_of<T>(runs: usize, mut f: impl FnMut() -> T) -> (f64, f64, T) {
    let (mut wall, mut cpu) = (f64::INFINITY, f64::INFINITY);
    let mut out = None;
    for _ in 0..runs {
        let (t, c) = (Instant::now(), cpu_seconds());
        let r = f();
        wall = wall.min(t.elapsed().as_secs_f64());
        cpu = cpu.min(cpu_seconds() - c);
        out = Some(r);
    }
    (wall, cpu, out.expect("at least one run"))
}

fn main() {
    let root = std::env::args()
        .nth(1)
        .unwrap_or_else(|| "/tmp/evalbench".into());
    let root = Path::new(&root);
    let threads = rayon::current_num_threads();
    let (t_dec, c_dec, n) = best_of(2, || decode_only(root));
    let opts = Options {
        split: Some(Split::All),
        ..Options::default()
    };
    let (t_eval, c_eval, report) = best_of(2, || {
        evaluate(&root.join("preds"), &root.join("gt"), &opts).expect("evaluate")
    });
    assert_eq!(report.images.len(), n);
    println!("images: {n}, threads: {threads}");
    println!(
        "decode only (4 PNGs per image): wall {t_dec:.2} s ({:.0} images/s), cpu {c_dec:.2} s",
        n as f64 / t_dec
    );
    println!(
        "evaluate (incl. bootstrap 1000): wall {t_eval:.2} s ({:.0} images/s), cpu {c_eval:.2} s",
        n as f64 / t_eval
    );
    println!(
        "ratio evaluate / decode: wall {:.2}, cpu {:.2}",
        t_eval / t_dec,
        c_eval / c_dec
    );
}
