//! The one id table of a dataset ([`IdTables`]): the integers of shapes, sizes, materials and
//! colours that every reader and export gives (the Python `Dataset`, the WebDataset and
//! Hugging Face shards, COCO's `category_id`), written beside each export as `ids.json`
//! ([`IdTables::to_json`]); and COCO's image and annotation ids, unique across the variants
//! of a dataset ([`coco_image_id`]).
//!
//! The rule (docs/output-format.md, "Ids"): each table is the built-in names in a fixed
//! order, the same for every variant and every export of this clevrtex version, then the
//! names the dataset adds:
//! - `shape`: the shapes the bridge builds, in its table's order (`KNOWN_SHAPES`: cube,
//!   sphere, cylinder, monkey, cone, torus, icosahedron, teapot);
//! - `size` and `color`: the built-in variants' names, the variants in their order (`full`
//!   first), a name kept at its first place;
//! - `material`: every material of the built-in catalogue (every set, so `--material-set`
//!   never leaves the table), sorted; then the user materials (`--materials DIR`) that any
//!   run manifest of the dataset records, sorted.
//!
//! Adding a variant to a dataset never moves a built-in id; only a new user material can
//! renumber the user materials after it.

use std::collections::BTreeSet;
use std::path::Path;
use std::sync::OnceLock;

use serde_json::{json, Value};

/// The tables, in the order `ids.json` lists them.
pub const TABLES: [&str; 4] = ["shape", "size", "material", "color"];

/// COCO image ids: `variant number * IMAGE_ID_STRIDE + index` ([`coco_image_id`]); indices
/// are below it (`clevrtex_scene::bounds::INDEX_END`).
pub const IMAGE_ID_STRIDE: u64 = clevrtex_scene::bounds::INDEX_END;
/// COCO annotation ids: `image id * ANNOTATION_ID_STRIDE + object index + 1` (an image has
/// at most 255 objects, `clevrtex_scene::scene_file::MAX_OBJECTS`).
pub const ANNOTATION_ID_STRIDE: u64 = 1000;
/// The first number of a variant that is not built in ([`variant_number`]).
const OTHER_VARIANTS_FROM: u64 = 100;
/// How many numbers the variants that are not built in hash into: the largest annotation id
/// stays below 2^53, so every JSON reader (JavaScript's included) reads it exactly.
const OTHER_VARIANTS: u64 = 89_000;

/// The id tables of a dataset: `shape[id]` is the name of shape `id`, and so on.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct IdTables {
    /// Shape names.
    pub shape: Vec<String>,
    /// Size names.
    pub size: Vec<String>,
    /// Material names (objects' and ground's).
    pub material: Vec<String>,
    /// Colour names (of the variants that colour objects).
    pub color: Vec<String>,
}

impl IdTables {
    /// The built-in tables (the rule of the module's docs, without user materials).
    pub fn builtin() -> &'static IdTables {
        static TABLES: OnceLock<IdTables> = OnceLock::new();
        TABLES.get_or_init(|| {
            use clevrtex_scene::config::Config;
            let mut size = Vec::new();
            let mut color = Vec::new();
            let push = |list: &mut Vec<String>, name: String| {
                if !list.contains(&name) {
                    list.push(name);
                }
            };
            for v in Config::variant_names() {
                let t = Config::builtin(v)
                    .expect("built-in configs are valid")
                    .name_tables();
                t.size.into_iter().for_each(|(n, _)| push(&mut size, n));
                t.color.into_iter().for_each(|n| push(&mut color, n));
            }
            let material: BTreeSet<String> = clevrtex_materials::Catalogue::builtin()
                .expect("the built-in catalogue is valid")
                .iter()
                .map(|m| m.name.clone())
                .collect();
            IdTables {
                shape: clevrtex_scene::names::KNOWN_SHAPES
                    .iter()
                    .map(|s| s.to_string())
                    .collect(),
                size,
                material: material.into_iter().collect(),
                color,
            }
        })
    }

    /// The tables of the dataset at `root` (an output folder or one variant's folder): the
    /// built-in ones, then the user materials that the run manifests of any of its variants
    /// record, sorted. Unreadable manifests are left out (`verify` reports them).
    pub fn of_dataset(root: &Path) -> Result<IdTables, String> {
        let ds = crate::dataset::Dataset::open(root).map_err(|e| e.to_string())?;
        let mut t = IdTables::builtin().clone();
        let mut user = BTreeSet::new();
        for vd in &ds.variants {
            user.extend(crate::fingerprint::user_materials(root, &vd.variant)?.into_keys());
        }
        for m in user {
            if !t.material.contains(&m) {
                t.material.push(m);
            }
        }
        Ok(t)
    }

    /// The table named `table` (one of [`TABLES`]).
    pub fn table(&self, table: &str) -> Option<&Vec<String>> {
        match table {
            "shape" => Some(&self.shape),
            "size" => Some(&self.size),
            "material" => Some(&self.material),
            "color" => Some(&self.color),
            _ => None,
        }
    }

    /// The table named `table`, to add a name to.
    fn table_mut(&mut self, table: &str) -> Option<&mut Vec<String>> {
        match table {
            "shape" => Some(&mut self.shape),
            "size" => Some(&mut self.size),
            "material" => Some(&mut self.material),
            "color" => Some(&mut self.color),
            _ => None,
        }
    }

    /// The id of `name` in `table`, if it is there.
    pub fn id(&self, table: &str, name: &str) -> Option<usize> {
        self.table(table)?.iter().position(|n| n == name)
    }

    /// The id of `name` in `table`, added at the end when it is not there (a name of a
    /// dataset someone else made: the export's `ids.json` lists it).
    pub fn id_or_add(&mut self, table: &str, name: &str) -> usize {
        let list = self.table_mut(table).expect("one of TABLES");
        match list.iter().position(|n| n == name) {
            Some(i) => i,
            None => {
                list.push(name.to_string());
                list.len() - 1
            }
        }
    }

    /// The tables as `{"shape": [...], "size": [...], "material": [...], "color": [...]}`.
    pub fn names_json(&self) -> Value {
        json!({
            "shape": self.shape,
            "size": self.size,
            "material": self.material,
            "color": self.color,
        })
    }

    /// `ids.json` of an export whose variants are `variants`: the tables, the rule, and each
    /// variant's number in COCO's image ids.
    pub fn to_json(&self, variants: &[&str]) -> Value {
        let numbers: serde_json::Map<String, Value> = variants
            .iter()
            .map(|v| (v.to_string(), json!(variant_number(v))))
            .collect();
        json!({
            "format": "clevrtex-ids",
            "version": 1,
            "rule": "ids index these tables: the built-in names in a fixed order (shapes in the bridge's order, sizes and colours in the built-in variants' order, every built-in material sorted), then the user materials the dataset's run manifests record, sorted (docs/output-format.md, \"Ids\")",
            "names": self.names_json(),
            "coco": {
                "image_id": format!("variant number * {IMAGE_ID_STRIDE} + image index"),
                "annotation_id": format!("image id * {ANNOTATION_ID_STRIDE} + object index + 1"),
                "category_id": "shape id + 1",
                "variant_numbers": numbers,
            },
        })
    }
}

/// A variant's number in COCO's image ids: 1 to 7 for the built-in variants in their order
/// (`full` 1, `pbg` 2, `vbg` 3, `grassbg` 4, `camo` 5, `outd` 6, `clevr` 7), else 100 plus its
/// name's content hash (`clevrtex_materials::content_hash`) modulo 89,000 (an export refuses two variants of one number).
pub fn variant_number(variant: &str) -> u64 {
    match clevrtex_scene::config::Config::variant_names()
        .iter()
        .position(|v| *v == variant)
    {
        Some(i) => i as u64 + 1,
        None => {
            OTHER_VARIANTS_FROM
                + clevrtex_materials::content_hash(&[variant.as_bytes()]) % OTHER_VARIANTS
        }
    }
}

/// The COCO image id of sample `index` of `variant`: `variant_number * 10^8 + index`, unique
/// across the variants of a dataset, so the COCO files of several variants merge.
pub fn coco_image_id(variant: &str, index: u64) -> u64 {
    variant_number(variant) * IMAGE_ID_STRIDE + index
}

/// The COCO annotation id of object `object` (its place in the metadata's `objects`) of the
/// image `image_id`.
pub fn coco_annotation_id(image_id: u64, object: usize) -> u64 {
    image_id * ANNOTATION_ID_STRIDE + object as u64 + 1
}

/// Two of `variants` that share a number ([`variant_number`]), if any.
pub fn number_clash<'a>(variants: &[&'a str]) -> Option<(&'a str, &'a str)> {
    for (i, a) in variants.iter().enumerate() {
        for b in &variants[i + 1..] {
            if a != b && variant_number(a) == variant_number(b) {
                return Some((a, b));
            }
        }
    }
    None
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn builtin_tables_hold_every_builtin_name_once() {
        let t = IdTables::builtin();
        assert_eq!(t.shape[..4], ["cube", "sphere", "cylinder", "monkey"]);
        assert_eq!(t.size, ["large", "medium", "small"]);
        assert_eq!(t.color[0], "gray");
        let mut sorted = t.material.clone();
        sorted.sort();
        sorted.dedup();
        assert_eq!(sorted, t.material);
        for v in clevrtex_scene::config::Config::variant_names() {
            let n = clevrtex_scene::config::Config::builtin(v)
                .unwrap()
                .name_tables();
            for m in &n.material {
                assert!(t.id("material", m).is_some(), "{v}: {m}");
            }
            for s in &n.shape {
                assert!(t.id("shape", s).is_some(), "{v}: {s}");
            }
        }
    }

    #[test]
    fn coco_ids_are_unique_across_variants_and_below_two_to_the_53() {
        assert_eq!(coco_image_id("full", 12), 100_000_012);
        assert_eq!(coco_image_id("clevr", 0), 700_000_000);
        assert_ne!(coco_image_id("full", 5), coco_image_id("camo", 5));
        let n = variant_number("my_variant");
        assert!((100..89_100).contains(&n));
        let largest = coco_annotation_id(
            (OTHER_VARIANTS_FROM + OTHER_VARIANTS) * IMAGE_ID_STRIDE - 1,
            254,
        );
        assert!(largest < 1 << 53, "{largest}");
        assert_eq!(number_clash(&["full", "camo", "my_variant"]), None);
    }
}
