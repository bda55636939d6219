//! The checks of one sample: its files, metadata, PNGs (decoded under a pixel budget shared
//! by the threads), kept EXRs and manifest entries.

use std::collections::BTreeMap;
use std::path::Path;

use clevrtex_scene::scene_file::MAX_IMAGE_SIDE;
use clevrtex_scene::Pass;
use serde_json::Value;

use crate::dataset::{self, MetadataView};
use crate::layout::{self};
use crate::manifest::{self, Manifest};

use super::report::*;

/// Check one sample; `Err` lists every problem found. `listed`: a finished manifest covers
/// the index, so every file must be in one.
/// Pixels of samples being decoded at once, over all threads: four samples of the largest size.
const PIXEL_BUDGET: u64 = 4 * (MAX_IMAGE_SIDE as u64) * (MAX_IMAGE_SIDE as u64);

/// A share of [`PIXEL_BUDGET`], held while a sample is decoded (waits while the budget is
/// spent; a sample larger than the whole budget waits for all of it).
struct PixelBudget(u64);

static BUDGET: (std::sync::Mutex<u64>, std::sync::Condvar) = (
    std::sync::Mutex::new(PIXEL_BUDGET),
    std::sync::Condvar::new(),
);

impl PixelBudget {
    fn take(pixels: u64) -> PixelBudget {
        let want = pixels.min(PIXEL_BUDGET);
        let (lock, freed) = &BUDGET;
        let mut left = lock.lock().unwrap_or_else(|e| e.into_inner());
        while *left < want {
            left = freed.wait(left).unwrap_or_else(|e| e.into_inner());
        }
        *left -= want;
        PixelBudget(want)
    }
}

impl Drop for PixelBudget {
    fn drop(&mut self) {
        let (lock, freed) = &BUDGET;
        *lock.lock().unwrap_or_else(|e| e.into_inner()) += self.0;
        freed.notify_all();
    }
}

/// Also the split the sample's metadata records (`None`: none, or not read). `runs`: the split
/// each run that covers the index gives it, with the run named.
#[allow(clippy::too_many_arguments)]
pub(super) fn check_sample(
    index: u64,
    stem: &str,
    f: &Found,
    entries: &Entries,
    listed_run: bool,
    claims: &[&ReadManifest],
    runs: &[(layout::Split, String)],
) -> (Option<layout::Split>, Result<(), Broken>) {
    let mut recorded = None;
    let mut problems = Vec::new();
    let variant_from_stem = layout::parse_stem(&format!("{stem}.json"), ".json")
        .map(|(_, v, _)| v.to_string())
        .unwrap_or_default();
    let want_dir = layout::sample_dir(
        f.variant_dir.parent().unwrap_or(Path::new("")),
        &variant_from_stem,
        index,
    );
    if want_dir != f.dir {
        problems.push(format!(
            "is in `{}`, not `{}`",
            f.dir.display(),
            want_dir.display()
        ));
    }
    let meta_name = layout::metadata_file(stem);
    let listed = entries.get(&(f.variant_dir.clone(), stem.to_string()));
    let mut bytes_of: BTreeMap<String, Vec<u8>> = BTreeMap::new();
    for name in &f.files {
        match dataset::read(&f.root, &f.dir.join(name), dataset::MAX_FILE_BYTES) {
            Ok(b) => {
                match listed.and_then(|l| l.get(name)) {
                    Some(es)
                        if !es
                            .iter()
                            .any(|e| e.size == b.len() as u64 && e.xxh3 == manifest::hash_hex(&b)) =>
                    {
                        problems.push(format!(
                            "`{name}` differs from the manifest ({} bytes, xxh3 {}; manifest: {} bytes, xxh3 {})",
                            b.len(),
                            manifest::hash_hex(&b),
                            es[0].size,
                            es[0].xxh3
                        ))
                    }
                    None if listed_run => {
                        problems.push(format!("`{name}` is not in any manifest"))
                    }
                    _ => {}
                }
                bytes_of.insert(name.clone(), b);
            }
            Err(why) => problems.push(format!("`{name}` {why}")),
        }
    }
    for name in listed.into_iter().flat_map(|l| l.keys()) {
        if !f.files.contains(name) {
            problems.push(format!("`{name}` is in the manifest but missing"));
        }
    }
    let Some(meta_bytes) = bytes_of.get(&meta_name) else {
        problems.push(format!("no metadata `{meta_name}` (an unfinished sample)"));
        return (recorded, Err(broken(index, stem, f, problems)));
    };
    let meta: Value = match serde_json::from_slice(meta_bytes) {
        Ok(v @ Value::Object(_)) => v,
        Ok(_) => {
            problems.push(format!("metadata `{meta_name}` is not a JSON object"));
            return (recorded, Err(broken(index, stem, f, problems)));
        }
        Err(e) => {
            problems.push(format!("metadata `{meta_name}` does not parse: {e}"));
            return (recorded, Err(broken(index, stem, f, problems)));
        }
    };
    // Every value that sizes or indexes something below, typed first.
    let view = match MetadataView::of(&meta, &meta_name) {
        Ok(v) => v,
        Err(e) => {
            problems.push(e.to_string());
            return (recorded, Err(broken(index, stem, f, problems)));
        }
    };
    let (w, h, n, threshold) = (
        view.width,
        view.height,
        view.num_objects,
        view.visibility_threshold_px,
    );
    let visible = &view.visible_pixels;
    // Decoding costs ~12 bytes a pixel over a sample's passes: however many threads check
    // samples, at most `PIXEL_BUDGET` pixels are decoded at once (about 0.8 GB), so that
    // samples declaring the largest size cannot add up to gigabytes on a many-core machine.
    let _budget = PixelBudget::take(u64::from(w) * u64::from(h));
    for (path, m, _) in claims {
        let differ = differs_from_manifest(&meta, &view, m);
        if !differ.is_empty() {
            problems.push(format!(
                "was not made by the run of the manifest `{}` that claims it (manifest vs metadata: {})",
                path.display(),
                differ.join(", ")
            ));
        }
    }
    // The recorded split (authoritative for every reader) must be the one the run that made
    // the sample gave it: the position rule over the run's `total`.
    match dataset::recorded_split(&meta["split"], &variant_from_stem, &meta_name) {
        Ok(Some(split)) => {
            recorded = Some(split);
            if !runs.is_empty() && !runs.iter().any(|(s, _)| *s == split) {
                problems.push(format!(
                    "metadata `split` is `{}`, but {} puts index {index} in `{}`",
                    split.name(),
                    runs[0].1,
                    runs[0].0.name()
                ));
            }
        }
        Ok(None) => {}
        Err(e) => problems.push(e.to_string()),
    }
    if meta["image_index"].as_u64() != Some(index) {
        problems.push(format!(
            "metadata `image_index` is {} (the file name says {index})",
            dataset::short(&meta["image_index"])
        ));
    }
    // Kept EXRs (`--keep-exr`): checked without a manifest too (their bytes are the
    // manifest's business when there is one).
    for (name, bytes) in bytes_of.iter().filter(|(n, _)| n.ends_with(".exr")) {
        if let Err(why) = crate::exr::check_kept(bytes, (w as usize, h as usize)) {
            problems.push(format!("`{name}` {why}"));
        }
    }
    let passes = view.passes.clone();
    if passes.is_empty() {
        problems.push("metadata lists no `passes`".into());
    }
    for pass in passes {
        let name = layout::pass_file(stem, pass);
        let key = pass.metadata_key();
        if meta[key].as_str() != Some(name.as_str()) {
            problems.push(format!(
                "metadata `{key}` is {} (expected \"{name}\")",
                dataset::short(&meta[key])
            ));
        }
        let Some(bytes) = bytes_of.get(&name) else {
            problems.push(format!("`{name}` is missing"));
            continue;
        };
        // The checks of every reader: size from the header before decoding, mode, decode,
        // mask ids ([`dataset::check_pass_png`], also `export`'s).
        let png = match dataset::check_pass_png(&name, bytes, pass, Some((w, h)), n) {
            Ok(p) => p,
            Err(problem) => {
                problems.push(problem);
                continue;
            }
        };
        if pass == Pass::Mask {
            let mut counts = vec![0u64; 256];
            for &v in &png.data {
                counts[(v as usize).min(255)] += 1;
            }
            for i in 1..=n {
                let listed = visible[i - 1];
                if counts[i] <= threshold {
                    problems.push(format!(
                        "object {i} has {} visible pixels, at or under the threshold {threshold}",
                        counts[i]
                    ));
                } else if listed.is_some_and(|l| l != counts[i]) {
                    problems.push(format!(
                        "object {i} has {} pixels in the mask but {} in the metadata",
                        counts[i],
                        listed.unwrap_or(0)
                    ));
                }
            }
        }
    }
    if problems.is_empty() {
        (recorded, Ok(()))
    } else {
        (recorded, Err(broken(index, stem, f, problems)))
    }
}

/// What of a sample's metadata differs from the run settings of the manifest `m` that claims
/// it: variant, seed, config hash (when the metadata records one), passes, each render setting
/// (size, samples, ...), one phrase each.
pub(super) fn differs_from_manifest(
    meta: &Value,
    view: &MetadataView,
    m: &Manifest,
) -> Vec<String> {
    let mut d = Vec::new();
    if meta["variant"].as_str() != Some(m.variant.as_str()) {
        d.push(format!(
            "variant {} vs {}",
            m.variant,
            dataset::short(&meta["variant"])
        ));
    }
    if meta["seed"].as_u64() != Some(m.seed) {
        d.push(format!(
            "seed {} vs {}",
            m.seed,
            dataset::short(&meta["seed"])
        ));
    }
    // Absent from older datasets (and `render`'s samples): not compared.
    if view
        .config_hash
        .as_ref()
        .is_some_and(|h| *h != m.config_hash)
    {
        d.push(format!(
            "config_hash {} vs {}",
            m.config_hash,
            dataset::short(&meta["config_hash"])
        ));
    }
    if !m.passes.is_empty() {
        let mut want: Vec<&str> = m.passes.iter().map(String::as_str).collect();
        let mut have: Vec<&str> = view.passes.iter().map(|p| p.name()).collect();
        want.sort_unstable();
        have.sort_unstable();
        if want != have {
            d.push(format!("passes {} vs {}", want.join(","), have.join(",")));
        }
    }
    if let Some(render) = &m.render {
        d.extend(manifest::render_differences(render, &meta["render"]));
    }
    // Each user material the sample records must be the manifest's, by content hash (absent
    // from samples of built-in materials only: not compared).
    match meta.get("user_materials") {
        None => {}
        Some(serde_json::Value::Object(um)) => {
            let recorded: Vec<(&String, &str)> = um
                .iter()
                .map(|(n, h)| (n, h.as_str().unwrap_or("(not a string)")))
                .collect();
            let used: BTreeMap<String, manifest::UserMaterial> = m
                .user_materials
                .iter()
                .filter(|(n, _)| um.contains_key(*n))
                .map(|(n, u)| (n.clone(), u.clone()))
                .collect();
            d.extend(manifest::user_materials_differ(&used, recorded));
        }
        Some(other) => d.push(format!(
            "user_materials {} is not an object",
            dataset::short(other)
        )),
    }
    d
}

pub(super) fn broken(index: u64, stem: &str, f: &Found, problems: Vec<String>) -> Broken {
    Broken {
        index,
        stem: stem.to_string(),
        dir: f.dir.clone(),
        problems,
        rerun_remakes: false,
    }
}
