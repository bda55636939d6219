//! Variant configs: the rules of a variant (shapes, sizes, materials, colours) plus the base
//! scene (camera, lights, backdrop, placement, render defaults).
//!
//! The built-in configs are the files of `configs/`, embedded at compile time, so an installed
//! binary never reads them at run time. A variant file may carry a `base_scene` object: it is
//! merged key by key over the built-in `configs/base-scene.json` (objects merge recursively,
//! any other value replaces), so a user config only states what it changes, e.g.
//! `"base_scene": {"render": {"samples": 256}}`. This crate does no I/O: the CLI reads a
//! user's file and calls [`Config::from_json_str`].

use std::collections::BTreeSet;
use std::sync::OnceLock;

use clevrtex_materials::Catalogue;
use serde::Deserialize;
use serde_json::Value;

use crate::bounds::{self, OutOfBounds};
pub use crate::names::{Splits, KNOWN_SHAPES};

mod overrides;
mod types;
pub use overrides::{
    check_index_end, parse_passes, parse_set, positive, recorded, within, Overrides,
};
pub use types::*;

/// The built-in base scene (the values of the public generator's `clevrtex-gen/generate.py`
/// and `data/scene.blend`, karazijal/clevrtex-generation).
pub const BASE_SCENE_JSON: &str = include_str!("../../../../configs/base-scene.json");

/// Built-in variants: name and file text, in the order `variant_names` lists them.
const BUILTIN: [(&str, &str); 7] = [
    ("full", include_str!("../../../../configs/full.json")),
    ("pbg", include_str!("../../../../configs/pbg.json")),
    ("vbg", include_str!("../../../../configs/vbg.json")),
    ("grassbg", include_str!("../../../../configs/grassbg.json")),
    ("camo", include_str!("../../../../configs/camo.json")),
    ("outd", include_str!("../../../../configs/outd.json")),
    ("clevr", include_str!("../../../../configs/clevr.json")),
];

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct VariantFile {
    name: String,
    #[serde(default)]
    description: String,
    splits: Splits,
    #[serde(default)]
    same_material: bool,
    objects: ObjectsFile,
    background: BackgroundFile,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct ObjectsFile {
    count: [u32; 2],
    shapes: Vec<String>,
    sizes: Vec<SizeRule>,
    materials: MaterialSelect,
    colors: Option<Vec<ColorRule>>,
    displacement: Option<f64>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct BackgroundFile {
    materials: Option<MaterialSelect>,
    displacement: Option<f64>,
    scale: Option<f64>,
}

/// `{"sets": [...], "include": [...], "exclude": [...]}`: members of the sets plus `include`,
/// minus `exclude`.
#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct MaterialSelect {
    #[serde(default)]
    sets: Vec<String>,
    #[serde(default)]
    include: Vec<String>,
    #[serde(default)]
    exclude: Vec<String>,
}

/// The built-in material catalogue, read once (names and sets select a variant's materials;
/// the recipes say which displace).
fn catalogue() -> &'static Catalogue {
    static CATALOGUE: OnceLock<Catalogue> = OnceLock::new();
    CATALOGUE.get_or_init(|| Catalogue::builtin().expect("built-in material catalogue is valid"))
}

impl Config {
    /// Names of the built-in variants.
    pub fn variant_names() -> Vec<&'static str> {
        BUILTIN.iter().map(|(n, _)| *n).collect()
    }

    /// The built-in variants' names, comma-separated, for help texts and hints.
    pub fn variant_list() -> String {
        Config::variant_names().join(", ")
    }

    /// The built-in config of `variant`.
    pub fn builtin(variant: &str) -> Result<Config, ConfigError> {
        Config::builtin_in(variant, catalogue())
    }

    /// The built-in config of `variant`, its material names resolved in `catalogue` (the
    /// built-in one plus a `--materials DIR`).
    pub fn builtin_in(variant: &str, catalogue: &Catalogue) -> Result<Config, ConfigError> {
        match BUILTIN.iter().find(|(n, _)| *n == variant) {
            Some((name, text)) => {
                Config::from_json_str_in(text, &format!("configs/{name}.json"), catalogue)
            }
            None => Err(ConfigError {
                file: "--variant".into(),
                key: "variant".into(),
                value: Some(variant.into()),
                problem: "unknown variant".into(),
                hint: format!(
                    "use one of {}, or copy one of `configs/` and pass it with `--config`",
                    Config::variant_list()
                ),
            }),
        }
    }

    /// Parse and validate a variant config. `source` names the file in error messages.
    pub fn from_json_str(text: &str, source: &str) -> Result<Config, ConfigError> {
        Config::from_json_str_in(text, source, catalogue())
    }

    /// Like [`Config::from_json_str`], material names and sets resolved in `catalogue` (so
    /// a config may name user materials, or `"sets": ["user"]`).
    pub fn from_json_str_in(
        text: &str,
        source: &str,
        catalogue: &Catalogue,
    ) -> Result<Config, ConfigError> {
        let err = |key: &str, value: Option<String>, problem: String, hint: &str| ConfigError {
            file: source.to_string(),
            key: key.to_string(),
            value,
            problem,
            hint: hint.to_string(),
        };
        let mut doc: Value = serde_json::from_str(text).map_err(|e| {
            err(
                ".",
                None,
                format!("not valid JSON: {e}"),
                "fix the JSON syntax at the line and column given",
            )
        })?;
        if !doc.is_object() {
            return Err(err(
                ".",
                None,
                "must be a JSON object, not a list or a single value".into(),
                "start from a copy of one of the built-in configs in `configs/`",
            ));
        }
        let mut base: Value =
            serde_json::from_str(BASE_SCENE_JSON).expect("built-in base scene is valid JSON");
        if let Some(obj) = doc.as_object_mut() {
            if let Some(over) = obj.remove("base_scene") {
                if !over.is_object() {
                    return Err(err(
                        "base_scene",
                        Some(over.to_string()),
                        "must be an object".into(),
                        "give only the keys to change, e.g. `{\"render\": {\"samples\": 256}}`",
                    ));
                }
                merge(&mut base, over);
            }
        }
        let file: VariantFile = serde_path_to_error::deserialize(&doc).map_err(|e| {
            err(
                &e.path().to_string(),
                None,
                e.inner().to_string(),
                "compare with the built-in configs in `configs/` and `docs/scene-format.md`",
            )
        })?;
        let base: BaseScene = serde_path_to_error::deserialize(&base).map_err(|e| {
            err(
                &format!("base_scene.{}", e.path()),
                None,
                e.inner().to_string(),
                "compare with `configs/base-scene.json`",
            )
        })?;
        validate(file, base, source, catalogue)
    }

    /// Draw the textured materials of the variant from `set` of `catalogue` instead
    /// (`generate --material-set`): every material list (objects, background) whose members
    /// are all in the textured sets `main` and `ood` becomes the whole of `set`; lists with
    /// a CLEVR material (`rubber`, `metal`, `plain`) or the grass background stay. Layouts do
    /// not change: the sampler draws materials from their own stream. Returns whether a list
    /// was replaced (`clevr` has none to replace).
    pub fn use_material_set(
        &mut self,
        catalogue: &Catalogue,
        set: clevrtex_materials::Set,
    ) -> Result<bool, ConfigError> {
        use clevrtex_materials::Set;
        let names: Vec<String> = catalogue.names(set).into_iter().map(String::from).collect();
        if names.is_empty() {
            return Err(ConfigError {
                file: "--material-set".into(),
                key: "material-set".into(),
                value: Some(set.name().into()),
                problem: "the set has no materials".into(),
                hint: "pass `--materials DIR` with the user materials, or another set".into(),
            });
        }
        let textured = |list: &[String]| {
            list.iter().all(|n| {
                catalogue
                    .get(n)
                    .is_some_and(|m| matches!(m.set, Set::Main | Set::Ood))
            })
        };
        let mut changed = false;
        if textured(&self.objects.materials) {
            self.objects.materials = names.clone();
            changed = true;
        }
        if textured(&self.background.materials) {
            self.background.materials = names.clone();
            changed = true;
        }
        if changed && self.objects.displacement.is_some() {
            self.objects.displacing = displacing(catalogue);
        }
        Ok(changed)
    }
}

/// The materials of `catalogue` that set up true displacement.
fn displacing(catalogue: &Catalogue) -> BTreeSet<String> {
    catalogue
        .iter()
        .filter(|m| m.displaces)
        .map(|m| m.name.clone())
        .collect()
}

/// Merge `over` into `base`: objects key by key (recursively), anything else replaces.
fn merge(base: &mut Value, over: Value) {
    match (base, over) {
        (Value::Object(b), Value::Object(o)) => {
            for (k, v) in o {
                match b.get_mut(&k) {
                    Some(slot) => merge(slot, v),
                    None => {
                        b.insert(k, v);
                    }
                }
            }
        }
        (slot, v) => *slot = v,
    }
}

fn validate(
    file: VariantFile,
    mut base: BaseScene,
    source: &str,
    catalogue: &Catalogue,
) -> Result<Config, ConfigError> {
    let err = |key: &str, value: Option<String>, problem: &str, hint: &str| ConfigError {
        file: source.to_string(),
        key: key.to_string(),
        value,
        problem: problem.to_string(),
        hint: hint.to_string(),
    };
    let out_of_bounds = |e: OutOfBounds| {
        ConfigError {
        file: source.to_string(),
        key: e.key,
        value: Some(e.value.to_string()),
        problem: e.problem,
        hint: "keep the value within its range; `docs/scene-format.md`, \"Bounds\", lists every bound and its reason".to_string(),
    }
    };
    if let Some(problem) = crate::names::variant_name_problem(&file.name) {
        return Err(err(
            "name",
            Some(file.name),
            &problem,
            "rename the variant, e.g. `my_variant`",
        ));
    }

    let [lo, hi] = file.objects.count;
    if lo == 0 || lo > hi || hi > 255 {
        return Err(err(
            "objects.count",
            Some(format!("[{lo}, {hi}]")),
            "must be `[min, max]` with 1 <= min <= max <= 255",
            "the reference uses `[3, 10]`",
        ));
    }
    if file.objects.shapes.is_empty() {
        return Err(err(
            "objects.shapes",
            Some("[]".into()),
            "must not be empty",
            "list at least one shape",
        ));
    }
    for (i, s) in file.objects.shapes.iter().enumerate() {
        if !KNOWN_SHAPES.contains(&s.as_str()) {
            return Err(err(
                &format!("objects.shapes[{i}]"),
                Some(s.clone()),
                "unknown shape",
                &format!("use one of {}", KNOWN_SHAPES.join(", ")),
            ));
        }
    }
    if file.objects.sizes.is_empty() {
        return Err(err(
            "objects.sizes",
            Some("[]".into()),
            "must not be empty",
            "list at least one size, e.g. `{\"name\": \"large\", \"scale\": 0.9}`",
        ));
    }
    for (i, s) in file.objects.sizes.iter().enumerate() {
        bounds::OBJECT_SCALE
            .check(&format!("objects.sizes[{i}].scale"), s.scale)
            .map_err(out_of_bounds)?;
    }
    let colors = match file.objects.colors {
        Some(c) if c.is_empty() => {
            return Err(err(
                "objects.colors",
                Some("[]".into()),
                "must not be empty",
                "remove the key for uncoloured objects, or list at least one colour",
            ))
        }
        Some(c) => c,
        None => Vec::new(),
    };
    let materials = resolve(
        &file.objects.materials,
        "objects.materials",
        catalogue,
        &err,
    )?;

    let bg_materials = match (&file.background.materials, file.same_material) {
        (Some(_), true) => {
            return Err(err(
                "background.materials",
                None,
                "must be absent when `same_material` is true (the background takes the objects' material)",
                "remove `background.materials` or set `same_material` to false",
            ))
        }
        (None, true) => materials.clone(),
        (None, false) => {
            return Err(err(
                "background.materials",
                None,
                "missing",
                "add e.g. `\"materials\": {\"include\": [\"plain\"]}`",
            ))
        }
        (Some(sel), false) => resolve(sel, "background.materials", catalogue, &err)?,
    };
    for (key, v, bound) in [
        (
            "objects.displacement",
            file.objects.displacement,
            &bounds::DISPLACEMENT,
        ),
        (
            "background.displacement",
            file.background.displacement,
            &bounds::DISPLACEMENT,
        ),
        (
            "background.scale",
            file.background.scale,
            &bounds::TEXTURE_SCALE,
        ),
    ] {
        if let Some(v) = v {
            bound.check(key, v).map_err(out_of_bounds)?;
        }
    }

    let displacing: BTreeSet<String> = match file.objects.displacement {
        None => BTreeSet::new(),
        Some(_) => displacing(catalogue),
    };

    // Base scene checks.
    let r = &base.render;
    use crate::scene_file::{MAX_IMAGE_SIDE, MAX_SAMPLES};
    let side = 1..=MAX_IMAGE_SIDE;
    if !side.contains(&r.width)
        || !side.contains(&r.height)
        || !(1..=MAX_SAMPLES).contains(&r.samples)
    {
        return Err(err(
            "base_scene.render",
            Some(format!("{}x{}, {} samples", r.width, r.height, r.samples)),
            &format!("width and height must be 1 to {MAX_IMAGE_SIDE}, samples 1 to {MAX_SAMPLES}"),
            "the reference uses 320x240",
        ));
    }
    if let Some(n) = r.shadow_samples {
        if !(1..=MAX_SAMPLES).contains(&n) {
            return Err(err(
                "base_scene.render.shadow_samples",
                Some(n.to_string()),
                &format!("must be 1 to {MAX_SAMPLES}"),
                "leave it out for three eighths of `samples` (24 at 64)",
            ));
        }
    }
    check_base_bounds(&base).map_err(out_of_bounds)?;
    if base.passes.is_empty() {
        return Err(err(
            "base_scene.passes",
            Some("[]".into()),
            "must not be empty",
            "list passes from rgb, mask, depth, normal, albedo, shadow",
        ));
    }
    base.passes.sort();
    base.passes.dedup();
    let p = &base.placement;
    if p.area[0] >= p.area[1] {
        return Err(err(
            "base_scene.placement.area",
            Some(format!("{:?}", p.area)),
            "must be `[lo, hi]` with lo < hi",
            "the reference uses area [-3, 3]",
        ));
    }
    let c = &base.camera;
    if c.clip_start >= c.clip_end {
        return Err(err(
            "base_scene.camera",
            Some(format!(
                "clip_start {}, clip_end {}",
                c.clip_start, c.clip_end
            )),
            "need clip_start < clip_end",
            "the reference uses 0.1 and 100",
        ));
    }
    let d = base.sun.direction;
    if d.iter().map(|v| v * v).sum::<f64>() < 1e-12 {
        return Err(err(
            "base_scene.sun.direction",
            Some(format!("{d:?}")),
            "must not be the zero vector (it is normalised)",
            "the reference uses [-0.414, 0.195, -0.889]",
        ));
    }

    Ok(Config {
        name: file.name,
        description: file.description,
        splits: file.splits,
        same_material: file.same_material,
        objects: ObjectRules {
            count: file.objects.count,
            shapes: file.objects.shapes,
            sizes: file.objects.sizes,
            materials,
            colors,
            displacement: file.objects.displacement,
            displacing,
        },
        background: BackgroundRules {
            materials: bg_materials,
            displacement: file.background.displacement,
            scale: file.background.scale,
        },
        base,
        layout_stream: None,
    })
}

/// Every number of the base scene within the one table of bounds ([`crate::bounds`]), so
/// that every scene sampled from it passes [`crate::SceneFile::validate`].
fn check_base_bounds(base: &BaseScene) -> Result<(), OutOfBounds> {
    crate::scene_file::check_render("base_scene.render", &base.render)?;
    let c = &base.camera;
    let k = |s: &str| format!("base_scene.camera.{s}");
    bounds::check_all(&bounds::POSITION, &k("location"), &c.location)?;
    bounds::check_all(&bounds::POSITION, &k("look_at"), &c.look_at)?;
    bounds::JITTER.check(&k("jitter"), c.jitter)?;
    bounds::FOCAL_LENGTH_MM.check(&k("focal_length_mm"), c.focal_length_mm)?;
    bounds::SENSOR_WIDTH_MM.check(&k("sensor_width_mm"), c.sensor_width_mm)?;
    bounds::CLIP_DISTANCE.check(&k("clip_start"), c.clip_start)?;
    bounds::CLIP_DISTANCE.check(&k("clip_end"), c.clip_end)?;
    for (i, l) in base.lights.iter().enumerate() {
        let k = |s: &str| format!("base_scene.lights[{i}].{s}");
        bounds::check_all(&bounds::POSITION, &k("location"), &l.location)?;
        bounds::check_all(&bounds::POSITION, &k("look_at"), &l.look_at)?;
        bounds::JITTER.check(&k("jitter"), l.jitter)?;
        bounds::LIGHT_SIZE_M.check(&k("size"), l.size)?;
        bounds::LIGHT_ENERGY_W.check(&k("energy"), l.energy)?;
        bounds::check_all(&bounds::COLOR, &k("color"), &l.color)?;
    }
    let s = &base.sun;
    bounds::check_all(&bounds::POSITION, "base_scene.sun.direction", &s.direction)?;
    bounds::SUN_STRENGTH.check("base_scene.sun.strength", s.strength)?;
    bounds::SUN_ANGLE.check("base_scene.sun.angle", s.angle)?;
    let b = &base.backdrop;
    bounds::check_backdrop("base_scene.backdrop", &b.profile, b.y_range)?;
    bounds::ROTATION_RAD.check("base_scene.backdrop.rotation_z", b.rotation_z)?;
    let p = &base.placement;
    bounds::check_all(
        &bounds::PLACEMENT_AREA,
        "base_scene.placement.area",
        &p.area,
    )?;
    bounds::PLACEMENT_GAP.check("base_scene.placement.min_dist", p.min_dist)?;
    bounds::PLACEMENT_GAP.check("base_scene.placement.margin", p.margin)?;
    bounds::PLACEMENT_TRIES.check(
        "base_scene.placement.tries_per_object",
        f64::from(p.tries_per_object),
    )?;
    bounds::PLACEMENT_TRIES.check(
        "base_scene.placement.max_restarts",
        f64::from(p.max_restarts),
    )?;
    Ok(())
}

/// Builds a [`ConfigError`] from key, value, problem and hint.
type MakeError<'a> = dyn Fn(&str, Option<String>, &str, &str) -> ConfigError + 'a;

fn resolve(
    sel: &MaterialSelect,
    key: &str,
    catalogue: &Catalogue,
    err: &MakeError<'_>,
) -> Result<Vec<String>, ConfigError> {
    let sets: BTreeSet<&str> = catalogue.iter().map(|m| m.set.name()).collect();
    let known = |name: &str| catalogue.get(name).is_some();
    let mut out = BTreeSet::new();
    for (i, s) in sel.sets.iter().enumerate() {
        if !sets.contains(s.as_str()) {
            return Err(err(
                &format!("{key}.sets[{i}]"),
                Some(s.clone()),
                "unknown material set",
                &format!(
                    "use one of {}",
                    sets.iter().copied().collect::<Vec<_>>().join(", ")
                ),
            ));
        }
        out.extend(
            catalogue
                .iter()
                .filter(|m| m.set.name() == s)
                .map(|m| m.name.clone()),
        );
    }
    for (field, names) in [("include", &sel.include), ("exclude", &sel.exclude)] {
        for (i, n) in names.iter().enumerate() {
            if known(n) {
                continue;
            }
            // The public generator's configs exclude its CLEVR base materials (`rubber`,
            // `mymetal`, `tabularasa`), which `--materials` never adds: excluding one is what
            // was asked, whether or not the folder held it; including one is an error that
            // names the built-in playing its part.
            let base = clevrtex_materials::CLEVR_BASE
                .iter()
                .find(|(name, _)| name == n);
            if let (Some(_), "exclude") = (base, field) {
                continue;
            }
            if let Some(&(name, builtin)) = base {
                let problem = match catalogue.clevr_base_named(name) {
                    Some(b) => b.left_out(),
                    None => format!(
                        "unknown material: the public generator's CLEVR base material \
                         `{name}`, which `--materials` never adds"
                    ),
                };
                return Err(err(
                    &format!("{key}.{field}[{i}]"),
                    Some(n.clone()),
                    &problem,
                    &format!("name the built-in `{builtin}`, which plays its part"),
                ));
            }
            return Err(err(
                &format!("{key}.{field}[{i}]"),
                Some(n.clone()),
                "unknown material",
                "run `clevrtex materials list` to see the catalogue",
            ));
        }
    }
    out.extend(sel.include.iter().cloned());
    for n in &sel.exclude {
        out.remove(n);
    }
    if out.is_empty() {
        return Err(err(
            key,
            None,
            "selects no material",
            "add a set (`\"sets\": [\"main\"]`) or names to `include`, or exclude fewer",
        ));
    }
    Ok(out.into_iter().collect())
}

#[cfg(test)]
mod tests;
