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
    configs: &Configs,
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
    let listed = entries.get(&f.variant_dir, stem);
    let mut bytes_of: BTreeMap<String, Vec<u8>> = BTreeMap::new();
    for name in &f.files {
        match dataset::read(&f.root, &f.dir.join(name), dataset::MAX_FILE_BYTES) {
            Ok(b) => {
                let hash = manifest::Xxh3::of(&b);
                match listed.and_then(|l| l.get(name)) {
                    Some(es)
                        if !es
                            .iter()
                            .any(|(_, e)| e.size == b.len() as u64 && e.xxh3 == hash) =>
                    {
                        problems.push(format!(
                            "`{name}` differs from the manifest ({} bytes, xxh3 {hash}; manifest: {} bytes, xxh3 {})",
                            b.len(),
                            es[0].1.size,
                            es[0].1.xxh3
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
    for name in listed.into_iter().flat_map(|l| l.names()) {
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
    let (w, h, n) = (view.width, view.height, view.num_objects);
    // Objects are checked against the image size's threshold, not the one the file claims.
    let threshold = clevrtex_scene::visibility::threshold(w, h);
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
    // The layout drawn again from the run's seed and config (verify by regeneration): a
    // forged field is found even where the manifest's hashes were rewritten to match.
    for (path, m, _) in claims {
        if let Some(Ok(config)) = configs.get(path) {
            let differ = super::rederive::differences(&meta, index, m, config);
            if !differ.is_empty() {
                problems.push(format!(
                    "does not re-derive from the seed and config of the manifest `{}` (metadata vs re-derived: {})",
                    path.display(),
                    differ.join(", ")
                ));
            }
        }
    }
    // The threshold every object was checked against is the image size's, whatever the
    // metadata says (0, or absent, would let any object pass).
    let want = clevrtex_scene::visibility::threshold(w, h);
    if meta.get("visibility_threshold_px").and_then(Value::as_u64) != Some(want) {
        problems.push(format!(
            "metadata `visibility_threshold_px` is {}, but a {w}x{h} image's is {want}",
            meta.get("visibility_threshold_px")
                .map_or("absent".to_string(), dataset::short)
        ));
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
            let mut boxes: Vec<Option<[u64; 4]>> = vec![None; 256];
            let width = (w as usize).max(1);
            for (at, &v) in png.data.iter().enumerate() {
                let id = (v as usize).min(255);
                counts[id] += 1;
                let (x, y) = ((at % width) as u64, (at / width) as u64);
                boxes[id] = Some(match boxes[id] {
                    None => [x, y, x, y],
                    Some([x0, y0, x1, y1]) => [x0.min(x), y0.min(y), x1.max(x), y1.max(y)],
                });
            }
            // Each object's box, where the metadata gives one, is the mask's (the COCO
            // export's boxes come from the mask).
            let objects = meta["objects"].as_array().map(Vec::as_slice).unwrap_or(&[]);
            for (i, o) in objects.iter().enumerate().take(n) {
                let Some(b) = o.get("bbox") else { continue };
                let listed: Option<Vec<u64>> = b
                    .as_array()
                    .map(|a| a.iter().filter_map(Value::as_u64).collect());
                let want = boxes[i + 1].map(|b| b.to_vec());
                let agrees = match (&listed, &want) {
                    (_, None) => b.is_null(),
                    (Some(l), Some(w)) => l == w,
                    _ => false,
                };
                if !agrees {
                    problems.push(format!(
                        "object {} has the box {} in the mask but {} in the metadata",
                        i + 1,
                        want.map_or("null".to_string(), |w| format!("{w:?}")),
                        dataset::short(b)
                    ));
                }
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
/// it: variant, seed, layout stream, config hash (absent is a difference), passes (a manifest
/// naming none is one too), each render setting (size, samples, ...), the user materials the
/// sample draws and records, one phrase each.
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
    if meta["layout_stream"].as_str() != Some(m.layout_stream()) {
        d.push(format!(
            "layout_stream {} vs {}",
            clevrtex_scene::text::printable(m.layout_stream()),
            dataset::short(&meta["layout_stream"])
        ));
    }
    // Every sample a `generate` run made records its run's config hash: one absent is not
    // "anything".
    if view.config_hash.as_deref() != Some(m.config_hash.as_str()) {
        d.push(format!(
            "config_hash {} vs {}",
            clevrtex_scene::text::printable(&m.config_hash),
            view.config_hash
                .as_ref()
                .map_or("(absent)".to_string(), |_| dataset::short(
                    &meta["config_hash"]
                ))
        ));
    }
    // The passes: an empty list in the manifest is a manifest that names none, not "anything".
    let mut want: Vec<&str> = m.passes.iter().map(String::as_str).collect();
    let mut have: Vec<&str> = view.passes.iter().map(|p| p.name()).collect();
    want.sort_unstable();
    have.sort_unstable();
    if want != have || want.is_empty() {
        d.push(format!(
            "passes {} vs {}",
            if want.is_empty() {
                "(none)".to_string()
            } else {
                clevrtex_scene::text::printable(&want.join(",")).into_owned()
            },
            have.join(",")
        ));
    }
    if let Some(render) = &m.render {
        d.extend(manifest::render_differences(render, &meta["render"]));
    }
    // Each user material the sample records must be the manifest's, by content hash (absent
    // from samples of built-in materials only: not compared).
    // The user materials the sample draws (its ground and objects' materials that the run's
    // manifest lists as user materials) must be the ones it records: none dropped.
    let drawn: std::collections::BTreeSet<&str> = std::iter::once(&meta["ground_material"])
        .chain(
            meta["objects"]
                .as_array()
                .map(Vec::as_slice)
                .unwrap_or(&[])
                .iter()
                .map(|o| &o["material"]),
        )
        .filter_map(Value::as_str)
        .filter(|n| m.user_materials.contains_key(*n))
        .collect();
    let recorded: std::collections::BTreeSet<&str> = meta
        .get("user_materials")
        .and_then(Value::as_object)
        .map(|um| um.keys().map(String::as_str).collect())
        .unwrap_or_default();
    if drawn != recorded {
        d.push(format!(
            "user materials drawn {} vs recorded {}",
            clevrtex_scene::text::printable(&drawn.iter().copied().collect::<Vec<_>>().join(",")),
            clevrtex_scene::text::printable(
                &recorded.iter().copied().collect::<Vec<_>>().join(",")
            )
        ));
    }
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
