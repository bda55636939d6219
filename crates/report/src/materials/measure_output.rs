//! What `clevrtex materials measure` prints: the tables of the per-variant and per-material
//! medians, or a JSON document with every image's figures and the summaries.

use std::fmt::Write as _;

use super::figures::{median, summarise, SampleFigures, Summary};

/// The JSON document: per variant and per material summaries, and every image's figures.
pub fn json(samples: &[SampleFigures]) -> serde_json::Value {
    let (variants, materials) = summarise(samples);
    let summary = |s: &Summary| {
        serde_json::json!({
            "images": s.images,
            "object_spread": s.object_spread,
            "background_spread": s.background_spread,
            "median_object_spread": median(&s.object_spread),
            "median_background_spread": median(&s.background_spread),
            "gradient_ratio": s.gradient,
            "median_gradient_ratio": median(&s.gradient),
            "scale": s.scale,
            "median_scale": median(&s.scale),
        })
    };
    let images: Vec<serde_json::Value> = samples
        .iter()
        .map(|s| {
            let by_id = |m: &std::collections::BTreeMap<u32, f64>| {
                m.iter()
                    .map(|(id, v)| (id.to_string(), serde_json::json!(v)))
                    .collect::<serde_json::Map<_, _>>()
            };
            serde_json::json!({
                "variant": s.variant,
                "stem": s.stem,
                "materials": s.materials.iter().map(|(id, m)| (id.to_string(), serde_json::json!(m))).collect::<serde_json::Map<_, _>>(),
                "albedo_spread": by_id(&s.spread),
                "gradient_ratio": s.gradient.as_ref().and_then(|g| g.ratio),
                "region_gradient_ratio": s.gradient.as_ref().map(|g| by_id(&g.regions)),
                "scale_q": by_id(&s.scale.q),
                "scale_ratio": s.scale.ratio,
            })
        })
        .collect();
    serde_json::json!({
        "variants": variants.iter().map(|(k, s)| (k.clone(), summary(s))).collect::<serde_json::Map<_, _>>(),
        "materials": materials.iter().map(|(k, s)| (k.clone(), summary(s))).collect::<serde_json::Map<_, _>>(),
        "images": images,
    })
}

/// The tables: per variant, then per material (sorted by median spread), then the legend.
pub fn tables(samples: &[SampleFigures]) -> String {
    let (variants, materials) = summarise(samples);
    let med = |v: &[f64]| median(v).unwrap_or(f64::NAN);
    // A figure with nothing measured prints as `-`.
    let f = |v: f64, digits: usize| {
        if v.is_nan() {
            "-".to_string()
        } else {
            format!("{v:.digits$}")
        }
    };
    let mut out = String::new();
    let _ = writeln!(
        out,
        "{:<10} {:>6} {:>13} {:>13} {:>22} {:>13}",
        "variant", "images", "spread obj", "spread bg", "gradient in/bnd", "scale bg/obj"
    );
    for (name, s) in &variants {
        let range = |v: &[f64]| {
            let lo = v.iter().copied().fold(f64::INFINITY, f64::min);
            let hi = v.iter().copied().fold(f64::NEG_INFINITY, f64::max);
            if v.is_empty() {
                "-".to_string()
            } else {
                format!("{:.2} ({lo:.2}-{hi:.2})", med(v))
            }
        };
        let _ = writeln!(
            out,
            "{:<10} {:>6} {:>13} {:>13} {:>22} {:>13}",
            clevrtex_scene::text::printable(name),
            s.images,
            f(med(&s.object_spread), 1),
            f(med(&s.background_spread), 1),
            range(&s.gradient),
            f(med(&s.scale), 2),
        );
    }
    let _ = writeln!(out);
    let _ = writeln!(
        out,
        "{:<26} {:>7} {:>10} {:>10} {:>9} {:>8}",
        "material", "regions", "spread obj", "spread bg", "gradient", "q"
    );
    let mut rows: Vec<(&String, &Summary)> = materials.iter().collect();
    rows.sort_by(|a, b| {
        let key = |s: &Summary| {
            let mut all = s.object_spread.clone();
            all.extend(&s.background_spread);
            med(&all)
        };
        key(a.1).total_cmp(&key(b.1)).then(a.0.cmp(b.0))
    });
    for (name, s) in rows {
        let regions = s.object_spread.len() + s.background_spread.len();
        let _ = writeln!(
            out,
            "{:<26} {:>7} {:>10} {:>10} {:>9} {:>8}",
            // A material name from the (untrusted) metadata: escaped.
            clevrtex_scene::text::printable(name),
            regions,
            f(med(&s.object_spread), 1),
            f(med(&s.background_spread), 1),
            f(med(&s.gradient), 2),
            f(med(&s.scale), 3),
        );
    }
    let _ = writeln!(
        out,
        "\nmedians; spread: CIELAB std of the albedo per region (photo textures: several times 3-5; goal >= 8);\ngradient: mean interior over mean boundary gradient of the 128x128 crop (photos ~0.37; goal >= 0.35);\nscale: q = D(1)/D(4) of the albedo's L, backdrop over objects (goal 0.9-1.1 on camo). docs/materials.md"
    );
    out
}
