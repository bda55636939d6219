//! Time sampling alone (no JSON, no files): `cargo run --release -p clevrtex-scene --example sample_speed`.

use std::time::Instant;

use clevrtex_scene::{config::Config, sample, to_pretty_json, SampleRequest};

fn main() {
    let n = 50_000;
    for variant in Config::variant_names() {
        let config = Config::builtin(variant).unwrap();
        let t = Instant::now();
        let scenes: Vec<_> = (0..n)
            .map(|index| {
                let req = SampleRequest {
                    seed: 1,
                    index,
                    attempt: 0,
                    total: n,
                };
                sample(&config, &req).unwrap()
            })
            .collect();
        let sampled = t.elapsed().as_secs_f64();
        let t = Instant::now();
        let bytes: usize = scenes
            .iter()
            .map(|s| to_pretty_json(s).unwrap().len())
            .sum();
        let json = t.elapsed().as_secs_f64();
        println!(
            "{variant:8} sample {sampled:.2} s, json {json:.2} s ({:.1} MB) for {n} scenes, one thread",
            bytes as f64 / 1e6
        );
    }
}
