//! What a dataset's samples are, apart from how they were rendered: each sample's metadata
//! with its provenance fields left out (the Blender version and compatibility switches, the
//! clevrtex version: they differ between machines and builds that make the same layouts), and
//! a fingerprint of a variant's layouts (xxh3 over every sample's stem and layout hash in index
//! order), so a paper can name exactly the layouts it used and `verify --against` can compare
//! two datasets made by one command.
//!
//! Also the user materials a dataset's runs record ([`user_materials`]): the names its
//! samples may carry beyond the built-in catalogue, for every reader's name tables.
//!
//! Metadata is untrusted: it is read capped and beneath the dataset's root
//! ([`crate::dataset::read`]), and a file that is not a JSON object has no layout hash.

use std::collections::BTreeMap;
use std::path::Path;

use serde_json::Value;

use crate::dataset;
use crate::manifest::{hash_hex, Manifest, UserMaterial};

/// Top-level metadata keys that say how and with what a sample was rendered, not what it
/// holds: left out of its layout hash.
pub const PROVENANCE_KEYS: &[&str] = &[
    "blender_version",
    "blender_compat",
    "clevrtex_version",
    "clevrtex_commit",
];

/// A sample's metadata without its [`PROVENANCE_KEYS`]; `None` if it is not a JSON object.
pub fn layout_of(meta: &[u8]) -> Option<Value> {
    let mut v: Value = serde_json::from_slice(meta).ok()?;
    let map = v.as_object_mut()?;
    for k in PROVENANCE_KEYS {
        map.remove(*k);
    }
    Some(v)
}

/// xxh3 (16 hex digits) of [`layout_of`] in a canonical form (keys sorted, compact).
pub fn layout_hash(meta: &[u8]) -> Option<String> {
    let v = layout_of(meta)?;
    Some(hash_hex(&serde_json::to_vec(&v).ok()?))
}

/// The materials a sample's metadata names (`ground_material`, each object's `material`).
fn materials_of(meta: &Value) -> impl Iterator<Item = &str> {
    let objects = meta["objects"].as_array().map(Vec::as_slice).unwrap_or(&[]);
    std::iter::once(&meta["ground_material"])
        .chain(objects.iter().map(|o| &o["material"]))
        .filter_map(Value::as_str)
}

/// One variant's layouts, from the metadata its finished runs list.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct Layouts {
    /// xxh3 over `stem` and layout hash of every sample in index order (16 hex digits);
    /// empty when no sample's metadata was read.
    pub fingerprint: String,
    /// Samples whose metadata went into it.
    pub samples: u64,
    /// Metadata files listed but not read (missing, unreadable, not an object).
    pub unread: u64,
    /// Each material the samples name, with how many of them name it.
    pub materials: BTreeMap<String, u64>,
}

/// The layouts of the samples the finished runs of `manifests` list, their metadata read
/// from `variant_dir` (beneath `root`, the dataset's canonical root).
pub fn layouts(root: &Path, variant_dir: &Path, manifests: &[&Manifest]) -> Layouts {
    // Each metadata file once, in index order (stems sort by index: zero-padded).
    let mut files: BTreeMap<(u64, String), &str> = BTreeMap::new();
    for m in manifests.iter().filter(|m| m.finished) {
        for rel in m.files.keys() {
            let name = rel.rsplit('/').next().unwrap_or(rel);
            if rel.contains("..") || !name.ends_with(".json") {
                continue;
            }
            if let Some((stem, _, index)) = crate::layout::parse_file_name(name) {
                files.insert((index, stem.to_string()), rel);
            }
        }
    }
    let mut out = Layouts::default();
    let mut all = Vec::new();
    for ((_, stem), rel) in files {
        let path = variant_dir.join(rel);
        let Some(meta) = dataset::read(root, &path, dataset::MAX_METADATA_BYTES)
            .ok()
            .and_then(|b| layout_of(&b))
        else {
            out.unread += 1;
            continue;
        };
        for m in materials_of(&meta) {
            *out.materials.entry(m.to_string()).or_insert(0) += 1;
        }
        let hash = hash_hex(&serde_json::to_vec(&meta).unwrap_or_default());
        all.extend_from_slice(stem.as_bytes());
        all.push(b' ');
        all.extend_from_slice(hash.as_bytes());
        all.push(b'\n');
        out.samples += 1;
    }
    if out.samples > 0 {
        out.fingerprint = hash_hex(&all);
    }
    out
}

/// The user materials (`--materials DIR`) that the run manifests of `variant` under `root` (an
/// output folder or a variant folder) record, by name: what a sample's material name may be
/// beyond the built-in catalogue (the Python `Dataset`'s and the export's name tables).
/// Unreadable manifests are left out (`verify` reports them).
pub fn user_materials(
    root: &Path,
    variant: &str,
) -> Result<BTreeMap<String, UserMaterial>, String> {
    let ds = dataset::Dataset::open(root).map_err(|e| e.to_string())?;
    let mut out = BTreeMap::new();
    for vd in ds.variants.iter().filter(|vd| vd.variant == variant) {
        for p in &vd.manifests {
            if let Ok(m) = Manifest::read(p) {
                out.extend(m.user_materials);
            }
        }
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn provenance_is_left_out_of_the_layout_hash_and_the_rest_is_not() {
        let a = br#"{"objects":[{"material":"wood"}],"blender_version":"3.4.1","clevrtex_version":"0.1.0"}"#;
        let b = br#"{"clevrtex_version":"0.2.0","objects":[{"material":"wood"}],"blender_version":"4.5.0","blender_compat":{"coat":true}}"#;
        let c = br#"{"objects":[{"material":"rock"}],"blender_version":"3.4.1"}"#;
        assert_eq!(layout_hash(a), layout_hash(b));
        assert_ne!(layout_hash(a), layout_hash(c));
        assert_eq!(layout_hash(b"[1]"), None);
        let v = layout_of(c).unwrap();
        assert_eq!(materials_of(&v).collect::<Vec<_>>(), ["rock"]);
    }
}
