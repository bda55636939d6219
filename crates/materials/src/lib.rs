//! The material catalogue: procedural materials as data, read and validated in Rust and
//! built by the Blender bridge (`blender_scripts/materials.py`).
//!
//! Every material is one JSON file under `materials/` plus one line in
//! `materials/catalogue.json`; the parameters each building block accepts, with their
//! defaults, are in `materials/blocks.json`. All of these files are embedded in the binary.
//! Validation names the file and the field of any mistake; resolution fills every default
//! and turns sRGB hex colours into linear floats, so the bridge receives complete recipes.
//!
//! ```
//! use clevrtex_materials::{Catalogue, Set};
//!
//! let cat = Catalogue::builtin()?;
//! assert!(cat.get("bricks").is_some());
//! assert_eq!(cat.names(Set::Basic), ["plain", "rubber", "metal"]);
//! // What the render crate writes as `materials.json` for the Blender workers:
//! let json = cat.resolved_json();
//! assert!(json.starts_with("{\"materials\":"));
//! # Ok::<(), clevrtex_materials::Error>(())
//! ```
//!
//! User materials (`--materials DIR`) are added with [`Catalogue::add_user_dir`]: `*.json`
//! files in our format (typically an `image` layer) and `*.blend` files holding a node group
//! with inputs Color / Random / Displacement / Scale and outputs Shader (or BSDF) and
//! Displacement. A user name equal to an existing one is an error, never a silent override.
//! The public generator's CLEVR base materials (`Rubber.blend`, `MyMetal.blend`,
//! `TabulaRasa.blend`, beside the textured ones in its `data/materials`) are recognised by
//! name and left out of the user set ([`CLEVR_BASE`], [`Catalogue::clevr_base`]).
#![deny(missing_docs)]

mod error;
mod hash;
pub mod pbr;
mod schema;
pub mod texture;
mod user;

use std::collections::BTreeMap;
use std::fmt;
use std::path::Path;
use std::sync::OnceLock;

use serde_json::Value;

pub use error::{Error, ErrorKind};
pub use hash::{content_hash, content_hash_of_parts, file_hash, open_regular};
use schema::Schema;
pub use user::{blend_file_problem, ClevrBase, CLEVR_BASE};

mod embedded {
    include!(concat!(env!("OUT_DIR"), "/embedded.rs"));
}

/// The catalogue file, embedded so an installed binary never hunts for it.
pub const CATALOGUE_JSON: &str = include_str!("../../../materials/catalogue.json");
/// The block schema (`materials/blocks.json`), embedded.
pub const BLOCKS_JSON: &str = include_str!("../../../materials/blocks.json");
/// Version of the resolved `materials.json` handed to the bridge.
pub const RESOLVED_VERSION: u32 = 1;

/// Which group a material belongs to.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub enum Set {
    /// `plain`, `rubber`, `metal`: the CLEVR-like materials.
    Basic,
    /// The GrassBG background material.
    Background,
    /// The main textured set.
    Main,
    /// The out-of-distribution set.
    Ood,
    /// Added from a `--materials DIR`.
    User,
}

impl Set {
    /// Every set, in catalogue order.
    pub const ALL: [Set; 5] = [Set::Basic, Set::Background, Set::Main, Set::Ood, Set::User];

    /// The set's name as written in `catalogue.json`.
    pub fn name(self) -> &'static str {
        match self {
            Set::Basic => "basic",
            Set::Background => "background",
            Set::Main => "main",
            Set::Ood => "ood",
            Set::User => "user",
        }
    }

    /// Parse a set name.
    pub fn from_name(name: &str) -> Option<Set> {
        Set::ALL.into_iter().find(|s| s.name() == name)
    }
}

impl fmt::Display for Set {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.pad(self.name())
    }
}

/// One validated, resolved material.
#[derive(Debug, Clone, PartialEq)]
pub struct Material {
    /// Catalogue name (stable: scene files refer to it).
    pub name: String,
    /// Its set.
    pub set: Set,
    /// The file it came from: catalogue-relative for built-ins, a path for user files.
    pub file: String,
    /// One-line description of the look.
    pub description: String,
    /// Whether the material sets up true displacement (when the instance and pass allow).
    pub displaces: bool,
    /// The resolved recipe the bridge receives.
    pub recipe: Value,
    /// Content hash of the recipe (and of a referenced `.blend` or image file): a cache key.
    pub hash: String,
}

/// The whole catalogue: built-ins plus any user materials.
#[derive(Debug, Clone)]
pub struct Catalogue {
    materials: Vec<Material>,
    /// The user directories added, canonical (the folders their textures must stay in).
    user_dirs: Vec<std::path::PathBuf>,
    /// The public generator's CLEVR base materials found in those directories, left out.
    clevr_base: Vec<ClevrBase>,
}

impl Catalogue {
    /// Read and validate the embedded catalogue.
    pub fn builtin() -> Result<Catalogue, Error> {
        let cat: Value = serde_json::from_str(CATALOGUE_JSON).map_err(|e| {
            Error::new(
                ErrorKind::Json,
                "catalogue.json",
                "",
                format!("invalid json: {e}"),
                "fix `materials/catalogue.json`",
            )
        })?;
        let entries = cat["materials"].as_array().ok_or_else(|| {
            Error::new(
                ErrorKind::MissingField,
                "catalogue.json",
                "materials",
                "missing array",
                "restore `materials/catalogue.json`",
            )
        })?;
        let mut out = Catalogue {
            materials: Vec::new(),
            user_dirs: Vec::new(),
            clevr_base: Vec::new(),
        };
        for (i, e) in entries.iter().enumerate() {
            let field = |k: &str| format!("materials[{i}].{k}");
            let get = |k: &str| {
                e[k].as_str().ok_or_else(|| {
                    Error::new(
                        ErrorKind::MissingField,
                        "catalogue.json",
                        &field(k),
                        "missing string",
                        "each entry is {\"name\", \"set\", \"file\"}",
                    )
                })
            };
            let (name, set, file) = (get("name")?, get("set")?, get("file")?);
            let set = Set::from_name(set)
                .filter(|s| *s != Set::User)
                .ok_or_else(|| {
                    Error::new(
                        ErrorKind::BadValue,
                        "catalogue.json",
                        &field("set"),
                        format!("unknown set `{set}`"),
                        "use basic, background, main or ood",
                    )
                })?;
            let text = embedded_file(file).ok_or_else(|| {
                Error::new(
                    ErrorKind::Io,
                    "catalogue.json",
                    &field("file"),
                    format!("material file `materials/{file}` does not exist"),
                    "create the file or fix the path (relative to `materials/`)",
                )
            })?;
            let m = Material::parse(name, set, file, text, None)?;
            out.insert(m)?;
        }
        Ok(out)
    }

    fn insert(&mut self, m: Material) -> Result<(), Error> {
        if let Some(old) = self.get(&m.name) {
            return Err(Error::new(
                ErrorKind::Clash,
                &m.file,
                "",
                format!(
                    "material name `{}` is already defined by `{}`",
                    m.name, old.file
                ),
                "rename the file: material names come from file names and must be unique",
            ));
        }
        self.materials.push(m);
        Ok(())
    }

    /// A material by name.
    pub fn get(&self, name: &str) -> Option<&Material> {
        self.materials.iter().find(|m| m.name == name)
    }

    /// A material by name, or an error naming the unknown material.
    pub fn require(&self, name: &str) -> Result<&Material, Error> {
        self.get(name).ok_or_else(|| {
            if let Some(b) = self.clevr_base_named(name) {
                return Error::new(
                    ErrorKind::UnknownMaterial,
                    &b.file.display().to_string(),
                    "",
                    b.left_out(),
                    format!("name the built-in `{}`, which plays its part", b.builtin),
                );
            }
            Error::new(
                ErrorKind::UnknownMaterial,
                "catalogue.json",
                "",
                format!("unknown material `{name}`"),
                "run `clevrtex materials list` to see the names",
            )
        })
    }

    /// Every material, in catalogue order (user materials last).
    pub fn iter(&self) -> impl Iterator<Item = &Material> {
        self.materials.iter()
    }

    /// The names of one set, in catalogue order.
    pub fn names(&self, set: Set) -> Vec<&str> {
        self.materials
            .iter()
            .filter(|m| m.set == set)
            .map(|m| m.name.as_str())
            .collect()
    }

    /// The resolved catalogue as the bridge's `materials.json`:
    /// `{"materials": {"<name>": <recipe>}, "version": 1}` (compact, keys sorted).
    pub fn resolved_json(&self) -> String {
        self.resolved_json_for(self.materials.iter().map(|m| m.name.as_str()))
    }

    /// Like [`Catalogue::resolved_json`], restricted to `names` (unknown names are skipped).
    pub fn resolved_json_for<'a>(&self, names: impl IntoIterator<Item = &'a str>) -> String {
        let mut map = BTreeMap::new();
        for n in names {
            if let Some(m) = self.get(n) {
                map.insert(m.name.clone(), m.recipe.clone());
            }
        }
        let v = serde_json::json!({"version": RESOLVED_VERSION, "materials": map});
        serde_json::to_string(&v).expect("json values always serialise")
    }

    /// Names of the building blocks the schema defines (the bridge implements the same).
    pub fn block_names() -> Vec<String> {
        schema().map(|s| s.block_names()).unwrap_or_default()
    }
}

impl Material {
    /// Validate one material file's text. `base_dir` resolves relative paths (user files);
    /// built-ins pass `None` and may not reference files.
    pub fn parse(
        name: &str,
        set: Set,
        file: &str,
        text: &str,
        base_dir: Option<&Path>,
    ) -> Result<Material, Error> {
        let v: Value = serde_json::from_str(text).map_err(|e| {
            Error::new(
                ErrorKind::Json,
                file,
                &format!("line {}, column {}", e.line(), e.column()),
                format!("invalid json: {e}"),
                "fix the syntax (a trailing comma or a missing quote is typical)",
            )
        })?;
        let recipe = schema()?.resolve(file, &v, base_dir)?;
        Ok(Material::from_recipe(
            name.to_string(),
            set,
            file.to_string(),
            recipe,
        ))
    }

    fn from_recipe(name: String, set: Set, file: String, mut recipe: Value) -> Material {
        let obj = recipe.as_object_mut().expect("recipes are objects");
        obj.insert("set".into(), set.name().into());
        // The recipe without the paths of its files (for a `.blend`, its group's name as the
        // file names it instead), so the hash says what the material is made of wherever its
        // folder lies or is copied to for a run (the run manifest's provenance, a resume's
        // settings), and the bytes of the files it references (a `.blend` and the images its
        // group reads, images, the maps of a PBR folder), each file hashed as it is read:
        // maps can be gigabytes.
        let mut parts = match (recipe["kind"].as_str(), recipe["group"].as_str()) {
            (Some("blend"), group) => {
                vec![xxhash_rust::xxh3::xxh3_64(group.unwrap_or("").as_bytes())]
            }
            _ => vec![xxhash_rust::xxh3::xxh3_64(
                &serde_json::to_vec(&without_paths(&recipe)).expect("json"),
            )],
        };
        let top = recipe.get("path").and_then(Value::as_str);
        let layers = recipe["layers"].as_array().into_iter().flatten();
        let maps = recipe["maps"].as_object().into_iter().flatten();
        let images = recipe["images"].as_object().into_iter().flatten();
        let paths = top
            .into_iter()
            .chain(layers.filter_map(|l| l["path"].as_str()))
            .chain(maps.filter_map(|(_, p)| p.as_str()))
            .chain(images.filter_map(|(_, p)| p.as_str()));
        parts.extend(paths.filter_map(|p| hash::file_hash(Path::new(p)).ok()));
        Material {
            description: recipe["description"].as_str().unwrap_or("").to_string(),
            displaces: recipe["displaces"].as_bool().unwrap_or(false),
            name,
            set,
            file,
            recipe,
            hash: format!("{:016x}", hash::content_hash_of_parts(&parts)),
        }
    }
}

/// `recipe` with the paths of the files it references blanked (`path`, each layer's `path`,
/// each value of `maps` and `images`): what of a recipe its hash covers beside the files.
fn without_paths(recipe: &Value) -> Value {
    let mut r = recipe.clone();
    let blank = |v: &mut Value| {
        if v.is_string() {
            *v = Value::String(String::new());
        }
    };
    if let Some(p) = r.get_mut("path") {
        blank(p);
    }
    let layers = r.get_mut("layers").and_then(Value::as_array_mut);
    for l in layers.into_iter().flatten() {
        if let Some(p) = l.get_mut("path") {
            blank(p);
        }
    }
    for key in ["maps", "images"] {
        let files = r.get_mut(key).and_then(Value::as_object_mut);
        for (_, p) in files.into_iter().flatten() {
            blank(p);
        }
    }
    r
}

fn schema() -> Result<&'static Schema, Error> {
    static SCHEMA: OnceLock<Result<Schema, Error>> = OnceLock::new();
    SCHEMA
        .get_or_init(|| Schema::parse(BLOCKS_JSON))
        .as_ref()
        .map_err(Clone::clone)
}

/// An 8-bit sRGB component as linear light in [0, 1] (the sRGB transfer function undone): the
/// project's one conversion, for material colours, variant colours (`clevrtex_scene`) and
/// image statistics. Here because every crate depends on this one.
pub fn srgb_to_linear(c: u8) -> f64 {
    let c = f64::from(c) / 255.0;
    if c <= 0.04045 {
        c / 12.92
    } else {
        ((c + 0.055) / 1.055).powf(2.4)
    }
}

/// Contents of an embedded file under `materials/` by relative path.
pub fn embedded_file(rel: &str) -> Option<&'static str> {
    embedded::EMBEDDED
        .iter()
        .find(|(p, _)| *p == rel)
        .map(|(_, t)| *t)
}
#[cfg(test)]
mod tests {
    use super::*;

    fn err(text: &str) -> Error {
        Material::parse("x", Set::User, "x.json", text, None).unwrap_err()
    }

    #[test]
    fn builtin_catalogue_validates_and_resolves_defaults() {
        let cat = Catalogue::builtin().unwrap();
        assert_eq!(cat.names(Set::Main).len(), 61);
        assert_eq!(cat.names(Set::Ood).len(), 25);
        assert_eq!(cat.names(Set::Background), ["mossy_forest_grass"]);
        let plain = &cat.get("plain").unwrap().recipe;
        assert_eq!(plain["layers"][0]["gap_roughness"], 0.9);
        assert_eq!(plain["surface"]["specular"], 0.5);
        let v: Value = serde_json::from_str(&cat.resolved_json()).unwrap();
        assert_eq!(v["materials"].as_object().unwrap().len(), 90);
    }

    #[test]
    fn colours_are_linearised() {
        let c = schema::parse_color(&Value::from("#ffffff")).unwrap();
        assert_eq!(c, [1.0, 1.0, 1.0]);
        let c = schema::parse_color(&Value::from("#808080")).unwrap();
        assert!((c[0] - 0.21586).abs() < 1e-4, "{c:?}");
        assert!(schema::parse_color(&Value::from("#80808")).is_none());
    }

    #[test]
    fn errors_name_file_and_field() {
        let e = err(r#"{"description": "d", "layers": [{"block": "bricks", "mortar": 1}]}"#);
        assert_eq!(e.kind, ErrorKind::UnknownField);
        assert_eq!(e.field, "layers[0].mortar");
        let shown = e.to_string();
        assert!(
            shown.contains("`x.json`") && shown.contains("\nhint: "),
            "{shown}"
        );

        let e = err(r#"{"description": "d", "layers": [{"block": "brick"}]}"#);
        assert_eq!(
            (e.kind, e.field.as_str()),
            (ErrorKind::UnknownBlock, "layers[0].block")
        );

        let e = err(r#"{"description": "d", "layers": [{"block": "noise", "scale": -1}]}"#);
        assert_eq!(
            (e.kind, e.field.as_str()),
            (ErrorKind::BadValue, "layers[0].scale")
        );

        let e =
            err(r##"{"description": "d", "layers": [{"block": "solid", "colors": ["#fff"]}]}"##);
        assert_eq!(e.field, "layers[0].colors[0]");

        let e = err(r#"{"layers": [{"block": "solid"}]}"#);
        assert_eq!(
            (e.kind, e.field.as_str()),
            (ErrorKind::MissingField, "description")
        );

        let e = err(r#"{"description": "d", "layers": [], "surface": {}}"#);
        assert_eq!(e.field, "layers");

        let e =
            err(r#"{"description": "d", "layers": [{"block": "solid"}], "surface": {"bmp": 1}}"#);
        assert_eq!(e.field, "surface.bmp");

        let e = err(r#"{"description": "d", "layers": [{"block": "solid"}],"#);
        assert_eq!(e.kind, ErrorKind::Json);
    }

    #[test]
    fn graph_links_must_not_dangle() {
        let g = |links: &str| {
            format!(
                r#"{{"description": "d", "layers": [{{"block": "graph",
                "nodes": {{"n": {{"type": "ShaderNodeTexNoise", "inputs": {{"Scale": 3}}}}}},
                "links": {links}}}]}}"#
            )
        };
        Material::parse(
            "x",
            Set::User,
            "x.json",
            &g(r#"[["coord", "n.Vector"], ["n.Fac", "out.fac"]]"#),
            None,
        )
        .unwrap();
        let e = err(&g(r#"[["coord", "m.Vector"]]"#));
        assert_eq!(
            (e.kind, e.field.as_str()),
            (ErrorKind::DanglingLink, "layers[0].links[0][1]")
        );
        let e = err(&g(r#"[["n.Fac", "out.colour"]]"#));
        assert_eq!(e.field, "layers[0].links[0][1]");
        let e = err(
            r#"{"description": "d", "layers": [{"block": "graph", "nodes": {"n": {"type": "Noise"}}, "links": []}]}"#,
        );
        assert_eq!(e.field, "layers[0].nodes.n.type");
    }

    #[test]
    fn user_dir_names_clash_with_builtins() {
        let dir = std::env::temp_dir().join(format!("clevrtex-mat-test-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        std::fs::write(
            dir.join("bricks.json"),
            r#"{"description": "d", "layers": [{"block": "solid"}]}"#,
        )
        .unwrap();
        let mut cat = Catalogue::builtin().unwrap();
        let e = cat.add_user_dir(&dir).unwrap_err();
        assert_eq!(e.kind, ErrorKind::Clash);
        std::fs::rename(dir.join("bricks.json"), dir.join("My Bricks.json")).unwrap();
        cat.add_user_dir(&dir).unwrap();
        assert_eq!(cat.get("my_bricks").unwrap().set, Set::User);
        std::fs::remove_dir_all(&dir).unwrap();
    }

    /// The public generator's `Rubber.blend`, `MyMetal.blend` and `TabulaRasa.blend` are its
    /// CLEVR base materials: left out of the user set, unread (not even a `.blend` header is
    /// needed), listed, and named by `require`; any other `.blend` named like a built-in
    /// still clashes.
    #[test]
    fn the_generators_clevr_base_materials_are_left_out_not_clashes() {
        let dir = std::env::temp_dir().join(format!("clevrtex-base-test-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        for f in ["Rubber.blend", "MyMetal.blend", "tabularasa.blend"] {
            std::fs::write(dir.join(f), b"not read").unwrap();
        }
        std::fs::write(
            dir.join("Bricks01.json"),
            r#"{"description": "d", "layers": [{"block": "solid"}]}"#,
        )
        .unwrap();
        let mut cat = Catalogue::builtin().unwrap();
        cat.add_user_dir(&dir).unwrap();
        assert_eq!(cat.names(Set::User), ["bricks01"]);
        assert_eq!(cat.get("rubber").unwrap().set, Set::Basic);
        let base: Vec<(&str, &str)> = cat
            .clevr_base()
            .iter()
            .map(|b| (b.name, b.builtin))
            .collect();
        assert_eq!(
            base,
            [
                ("mymetal", "metal"),
                ("rubber", "rubber"),
                ("tabularasa", "plain")
            ]
        );
        let e = cat.require("mymetal").unwrap_err();
        assert_eq!(e.kind, ErrorKind::UnknownMaterial);
        let shown = e.to_string();
        assert!(
            shown.contains("MyMetal.blend") && shown.contains("built-in `metal`"),
            "{shown}"
        );
        // Another built-in's name is still a clash, naming both files.
        std::fs::write(dir.join("Metal.blend"), b"BLENDER-v304").unwrap();
        let e = Catalogue::builtin()
            .unwrap()
            .add_user_dir(&dir)
            .unwrap_err();
        assert_eq!(e.kind, ErrorKind::Clash);
        let shown = e.to_string();
        assert!(
            shown.contains("Metal.blend")
                && shown.contains("already defined by `basic/metal.json`"),
            "{shown}"
        );
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
