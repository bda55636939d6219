//! Verify by regeneration: the sampler is pure and cheap, so each sample's layout is drawn
//! again from what the manifest that claims it records (seed, layout stream, config, `--total`)
//! and the sample's index and accepted attempt, and compared with its metadata: objects
//! (shape, size, material, colour, position, rotation, pixel coordinates), camera, ground
//! material, directions, relationships, split, render settings, passes and the visibility
//! threshold of the image size. A forged field is found even when the forger rewrote the
//! manifest's file hashes. What the sampler does not decide (visible pixels and boxes) is
//! checked against the mask by [`super::checks`].
//!
//! The run's config is rebuilt from the manifest's settings by
//! [`clevrtex_scene::config::recorded`] (the one whose hash is the manifest's `config_hash`);
//! a run of a config given with `--config` or of user materials cannot be rebuilt, and its
//! samples are then not re-derived (said in the report, not a failure).

use serde_json::{json, Value};

use clevrtex_scene::scene_file::RenderSettings;
use clevrtex_scene::{Config, Pass, SampleRequest};

use crate::dataset::short;
use crate::manifest::Manifest;

/// The most layout attempts per image (`generate --max-attempts`' ceiling): an `attempt` at
/// or past it was never accepted by a run.
const MAX_ATTEMPTS: u64 = 1000;

/// Object keys the sampler does not decide (counted from the mask, checked against it).
const FROM_THE_MASK: &[&str] = &["visible_pixels", "bbox"];

/// The config of the run of `m`, rebuilt from its settings; `Err` says why it cannot be.
pub(crate) fn config_of(m: &Manifest) -> Result<Config, String> {
    let stream = m
        .layout_stream
        .as_deref()
        .ok_or("the manifest records no `layout_stream` (a clevrtex 0.1 run)")?;
    let render = m
        .render
        .clone()
        .ok_or("the manifest records no `render` settings (an older run)")?;
    let render: RenderSettings = serde_json::from_value(render)
        .map_err(|e| format!("the manifest's `render` does not read: {e}"))?;
    let mut passes = Vec::new();
    for name in &m.passes {
        passes.push(Pass::from_name(name).ok_or_else(|| {
            format!(
                "the manifest names an unknown pass `{}`",
                clevrtex_scene::text::printable(name)
            )
        })?);
    }
    passes.sort();
    clevrtex_scene::config::recorded(&m.variant, Some(stream), &render, &passes, &m.config_hash)
}

/// Whether two numbers agree to about 1e-9 of their size (the sampler's arithmetic, written
/// by one formatter; a margin for another machine's `sin`).
fn close(a: f64, b: f64) -> bool {
    a == b || (a - b).abs() <= 1e-9 * a.abs().max(b.abs()).max(1.0)
}

/// Whether `have` (the file's) is `want` (re-derived) as values: numbers [`close`], objects
/// key by key, arrays item by item.
fn agrees(have: &Value, want: &Value) -> bool {
    match (have, want) {
        (Value::Number(x), Value::Number(y)) => match (x.as_f64(), y.as_f64()) {
            (Some(a), Some(b)) => close(a, b),
            _ => false,
        },
        (Value::Array(x), Value::Array(y)) => {
            x.len() == y.len() && x.iter().zip(y).all(|(p, q)| agrees(p, q))
        }
        (Value::Object(x), Value::Object(y)) => {
            x.len() == y.len()
                && y.iter()
                    .all(|(k, v)| x.get(k).is_some_and(|w| agrees(w, v)))
        }
        _ => have == want,
    }
}

/// What of the metadata `meta` of sample `index` differs from its layout drawn again with
/// `config` (the run of `m`'s), one phrase each (`objects[0].material "x" (re-derived "y")`).
pub(crate) fn differences(meta: &Value, index: u64, m: &Manifest, config: &Config) -> Vec<String> {
    let attempt = match meta["attempt"].as_u64() {
        Some(a) if a < MAX_ATTEMPTS => a as u32,
        _ => {
            return vec![format!(
                "metadata `attempt` is {}, not a layout attempt a run accepts (0 to {})",
                short(&meta["attempt"]),
                MAX_ATTEMPTS - 1
            )]
        }
    };
    let req = SampleRequest {
        seed: m.seed,
        index,
        attempt,
        total: m.total,
    };
    let mut scene = match clevrtex_scene::sample(config, &req) {
        Ok(s) => s,
        Err(e) => return vec![format!("its layout cannot be drawn again: {e}")],
    };
    scene.passes = config.base.passes.clone();
    let Ok(Value::Object(mut want)) = serde_json::to_value(clevrtex_scene::metadata(&scene)) else {
        return vec!["its layout cannot be drawn again: the metadata does not serialise".into()];
    };
    let (w, h) = (scene.render.width, scene.render.height);
    let encodings: serde_json::Map<String, Value> = scene
        .passes
        .iter()
        .map(|p| (p.name().to_string(), json!(p.spec().encoding)))
        .collect();
    for (k, v) in [
        ("variant", json!(scene.variant)),
        ("stem", json!(scene.stem)),
        ("seed", json!(scene.seed)),
        ("layout_stream", json!(scene.layout_stream)),
        ("config_hash", json!(m.config_hash)),
        ("attempt", json!(scene.attempt)),
        (
            "camera",
            json!(clevrtex_scene::metadata::CameraMetadata::of(&scene)),
        ),
        (
            "visibility_threshold_px",
            json!(clevrtex_scene::visibility::threshold(w, h)),
        ),
        ("passes", Value::Object(encodings)),
        ("render", json!(scene.render)),
    ] {
        want.insert(k.to_string(), v);
    }
    let mut out = Vec::new();
    let mut differ = |key: String, have: Option<&Value>, want: &Value| {
        if out.len() < 20 {
            out.push(format!(
                "`{key}` {} (re-derived: {})",
                have.map_or("absent".to_string(), short),
                short(want)
            ));
        }
    };
    for (k, v) in &want {
        if k != "objects" {
            if !meta.get(k).is_some_and(|have| agrees(have, v)) {
                differ(k.clone(), meta.get(k), v);
            }
            continue;
        }
        let (have, want) = (
            meta["objects"].as_array().map(Vec::as_slice).unwrap_or(&[]),
            v.as_array().map(Vec::as_slice).unwrap_or(&[]),
        );
        if have.len() != want.len() {
            differ(
                "objects".into(),
                Some(&json!(format!("{} objects", have.len()))),
                &json!(format!("{} objects", want.len())),
            );
            continue;
        }
        for (i, (ho, wo)) in have.iter().zip(want).enumerate() {
            let (Some(ho), Some(wo)) = (ho.as_object(), wo.as_object()) else {
                differ(format!("objects[{i}]"), Some(ho), wo);
                continue;
            };
            for (ok, ov) in wo {
                if !ho.get(ok).is_some_and(|x| agrees(x, ov)) {
                    differ(format!("objects[{i}].{ok}"), ho.get(ok), ov);
                }
            }
            for (ok, ov) in ho {
                if !wo.contains_key(ok) && !FROM_THE_MASK.contains(&ok.as_str()) {
                    differ(format!("objects[{i}].{ok}"), Some(ov), &Value::Null);
                }
            }
        }
    }
    out
}
