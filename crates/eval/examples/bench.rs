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

fn best_of<T>(runs: usize, mut f: impl FnMut() -> T) -> (f64, T) {
    let mut best = f64::INFINITY;
    let mut out = None;
    for _ in 0..runs {
        let t = Instant::now();
        let r = f();
        best = best.min(t.elapsed().as_secs_f64());
        out = Some(r);
    }
    (best, out.expect("at least one run"))
}

fn main() {
    let root = std::env::args()
        .nth(1)
        .unwrap_or_else(|| "/tmp/evalbench".into());
    let root = Path::new(&root);
    let threads = rayon::current_num_threads();
    let (t_dec, n) = best_of(2, || decode_only(root));
    let opts = Options {
        split: Some(Split::All),
        ..Options::default()
    };
    let (t_eval, report) = best_of(2, || {
        evaluate(&root.join("preds"), &root.join("gt"), &opts).expect("evaluate")
    });
    assert_eq!(report.images.len(), n);
    println!("images: {n}, threads: {threads}");
    println!(
        "decode only (4 PNGs per image): {t_dec:.2} s, {:.0} images/s",
        n as f64 / t_dec
    );
    println!(
        "evaluate (incl. bootstrap 1000): {t_eval:.2} s, {:.0} images/s",
        n as f64 / t_eval
    );
    println!("ratio evaluate / decode: {:.2}", t_eval / t_dec);
}
