//! How often `generate`'s geometric pre-reject and pre-accept fire: the share of first-attempt
//! layouts of a variant with an object bounded at or under the visibility threshold, and the
//! share whose every object is bounded from below over it (no Blender needed).
//!
//! `cargo run --release -p clevrtex-scene --example prereject_rate -- full 2000`

use clevrtex_scene::config::Config;
use clevrtex_scene::visibility::{threshold, visible_pixel_bounds, visible_pixel_lower_bounds};
use clevrtex_scene::{sample, SampleRequest};

fn main() {
    let mut args = std::env::args().skip(1);
    let variant = args.next().unwrap_or_else(|| "full".into());
    let n: u64 = args.next().map_or(2000, |v| v.parse().expect("a count"));
    let config = Config::builtin(&variant).expect("a built-in variant");
    let (w, h) = (config.base.render.width, config.base.render.height);
    let threshold = threshold(w, h);
    let t = std::time::Instant::now();
    let mut pre = 0;
    let mut accepted = 0;
    for index in 0..n {
        let req = SampleRequest {
            seed: 0,
            index,
            attempt: 0,
            total: n,
        };
        let scene = sample(&config, &req).expect("a layout");
        let bounds = visible_pixel_bounds(&scene).expect("a bound");
        if bounds.iter().any(|&b| b <= threshold) {
            pre += 1;
        }
        let lower = visible_pixel_lower_bounds(&scene).expect("a bound");
        if lower.iter().all(|&b| b > threshold) {
            accepted += 1;
        }
    }
    println!(
        "{variant} {w}x{h}: of {n} first-attempt layouts {pre} pre-rejected ({:.1}%), {accepted} pre-accepted ({:.1}%); {:.2} ms per layout",
        100.0 * pre as f64 / n as f64,
        100.0 * accepted as f64 / n as f64,
        t.elapsed().as_secs_f64() * 1e3 / n as f64
    );
}
