//! The data of a variant config: the loaded, validated [`Config`] with its rules and base
//! scene, and [`ConfigError`]. Loading and validation are in the parent module.

use std::collections::BTreeSet;

use serde::{Deserialize, Serialize};

use crate::names::Splits;
use crate::scene_file::{Pass, RenderSettings};

/// A config that failed to load: the file, the key and the value at fault, and what to do.
///
/// An unknown `--variant` (file `--variant`) reads `unknown variant `x``; an error in the whole
/// document (key `.`, e.g. bad JSON) names no key.
#[derive(Debug, Clone, PartialEq)]
pub struct ConfigError {
    /// The file (or built-in name) the config came from.
    pub file: String,
    /// Dotted path of the offending key (`.` for the whole document).
    pub key: String,
    /// The offending value, when there is one.
    pub value: Option<String>,
    /// What is wrong.
    pub problem: String,
    /// What to do about it.
    pub hint: String,
}

impl std::fmt::Display for ConfigError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let value = self
            .value
            .as_ref()
            .map(|v| format!(" (value `{v}`)"))
            .unwrap_or_default();
        let (file, key, problem, hint) = (&self.file, &self.key, &self.problem, &self.hint);
        match (file.as_str(), key.as_str()) {
            ("--variant", _) => write!(
                f,
                "{problem} `{}`",
                self.value.as_deref().unwrap_or_default()
            )?,
            (_, ".") => write!(f, "invalid config `{file}`: {problem}")?,
            _ => write!(f, "invalid config `{file}`: key `{key}`{value}: {problem}")?,
        }
        write!(f, "\nhint: {hint}")
    }
}

impl std::error::Error for ConfigError {}

/// A size class: name and the scale applied to the unit mesh.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SizeRule {
    /// `large`, `medium`, `small` or any name.
    pub name: String,
    /// Scale factor (also the object's radius in the spacing rule).
    pub scale: f64,
}

/// A named colour in sRGB 0-255, as CLEVR lists them.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ColorRule {
    /// Colour name recorded in metadata.
    pub name: String,
    /// sRGB components, 0-255.
    pub srgb: [u8; 3],
}

impl ColorRule {
    /// The colour in linear RGB (the sRGB transfer function undone), as Blender wants it.
    pub fn linear(&self) -> [f64; 3] {
        self.srgb.map(clevrtex_materials::srgb_to_linear)
    }
}

/// Object rules of a variant, with the material list resolved to names.
#[derive(Debug, Clone, PartialEq)]
pub struct ObjectRules {
    /// Inclusive range of the object count, drawn uniformly once per image.
    pub count: [u32; 2],
    /// Shapes, drawn uniformly.
    pub shapes: Vec<String>,
    /// Sizes, drawn uniformly.
    pub sizes: Vec<SizeRule>,
    /// Material names, drawn uniformly (sorted, no duplicates).
    pub materials: Vec<String>,
    /// Colours, drawn uniformly; empty when the variant does not colour objects.
    pub colors: Vec<ColorRule>,
    /// Displacement strength recorded on object materials that displace (`objects.displacement`);
    /// `None` (the default) = objects use bump only.
    pub displacement: Option<f64>,
    /// Catalogue materials that set up true displacement; filled only when `displacement` is
    /// set.
    pub displacing: BTreeSet<String>,
}

impl ObjectRules {
    /// The displacement strength to record on an object instance of material `name`.
    pub fn displacement_for(&self, name: &str) -> Option<f64> {
        self.displacement.filter(|_| self.displacing.contains(name))
    }
}

/// Background rules of a variant.
#[derive(Debug, Clone, PartialEq)]
pub struct BackgroundRules {
    /// Material names, drawn uniformly (the object's material when `same_material`).
    pub materials: Vec<String>,
    /// Displacement strength of the backdrop material, if it displaces.
    pub displacement: Option<f64>,
    /// Texture scale of the backdrop material, if set.
    pub scale: Option<f64>,
}

/// Camera of the base scene before jitter.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CameraRig {
    /// Location before jitter.
    pub location: [f64; 3],
    /// Point tracked.
    pub look_at: [f64; 3],
    /// Each coordinate of `location` moves by Uniform(-jitter, jitter).
    pub jitter: f64,
    /// Focal length, mm.
    pub focal_length_mm: f64,
    /// Sensor width, mm (sensor fit `AUTO`).
    pub sensor_width_mm: f64,
    /// Near clip.
    pub clip_start: f64,
    /// Far clip.
    pub clip_end: f64,
}

/// An area light of the base scene before jitter.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct LightRig {
    /// `key`, `fill`, `back`.
    pub name: String,
    /// Location before jitter.
    pub location: [f64; 3],
    /// Point tracked.
    pub look_at: [f64; 3],
    /// Each coordinate of `location` moves by Uniform(-jitter, jitter).
    pub jitter: f64,
    /// Side of the square, m.
    pub size: f64,
    /// Power, W.
    pub energy: f64,
    /// Linear RGB.
    pub color: [f64; 3],
}

/// The sun of the base scene.
// Like the scene file's `Sun` and `Backdrop` by design, not by copy: the scene file's types
// cannot embed these (serde's `flatten` does not go with `deny_unknown_fields`, which untrusted
// scene files need, and nesting would change the scene file's bytes).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SunRig {
    /// Direction the light travels (normalised by the sampler).
    pub direction: [f64; 3],
    /// Strength.
    pub strength: f64,
    /// Angular diameter, rad.
    pub angle: f64,
}

/// The backdrop's shape.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct BackdropShape {
    /// `[x, height]` profile points, x increasing.
    pub profile: Vec<[f64; 2]>,
    /// Extent along the backdrop's y.
    pub y_range: [f64; 2],
    /// Rotation about world z, rad.
    pub rotation_z: f64,
}

/// Placement rules (as the public generator's `clevrtex-gen/generate.py` places objects,
/// karazijal/clevrtex-generation; Karazija et al., NeurIPS 2021 Datasets and Benchmarks).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Placement {
    /// Object centres are drawn from `[area.0, area.1]^2`.
    pub area: [f64; 2],
    /// Minimum gap between two objects' radii.
    pub min_dist: f64,
    /// Projected offsets along left/right/front/behind must not fall in `(0, margin)`.
    pub margin: f64,
    /// Position draws per object before the whole layout restarts.
    pub tries_per_object: u32,
    /// Layout restarts before giving up with an error.
    pub max_restarts: u32,
    /// Divide a placed cube's recorded radius by sqrt(2), as CLEVR does.
    pub cube_radius_quirk: bool,
}

/// The base scene: everything that is the same for every variant.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct BaseScene {
    /// Render defaults.
    pub render: RenderSettings,
    /// Passes requested by default.
    pub passes: Vec<Pass>,
    /// Camera.
    pub camera: CameraRig,
    /// Area lights.
    pub lights: Vec<LightRig>,
    /// Sun.
    pub sun: SunRig,
    /// Backdrop.
    pub backdrop: BackdropShape,
    /// Placement rules.
    pub placement: Placement,
}

/// A loaded and validated config.
#[derive(Debug, Clone, PartialEq)]
pub struct Config {
    /// Variant name, used in file names (`[A-Za-z0-9_-]+`).
    pub name: String,
    /// One line saying what the variant is.
    pub description: String,
    /// Split rule.
    pub splits: Splits,
    /// One material per scene, on every object and the background (CAMO).
    pub same_material: bool,
    /// Object rules.
    pub objects: ObjectRules,
    /// Background rules.
    pub background: BackgroundRules,
    /// Base scene.
    pub base: BaseScene,
    /// The layout stream the sampler draws from when it is not the variant's own (`None`, the
    /// default: the same seed gives unrelated layouts in every variant). Set by
    /// `--layout-stream` ([`Config::set_layout_stream`]), never by a config file.
    pub layout_stream: Option<String>,
}

impl Config {
    /// The layout stream the sampler draws from: `--layout-stream`'s, else the variant's
    /// name. Two variants with one stream (and seed) get the same layouts where their rules
    /// agree: the controlled comparison of materials; [`crate::rng::SHARED_STREAM`] is the one
    /// stream every variant drew from up to clevrtex 0.1.
    pub fn layout_stream(&self) -> &str {
        self.layout_stream.as_deref().unwrap_or(&self.name)
    }

    /// Draw layouts from `stream` ([`Config::layout_stream`]); the variant's own name is the
    /// default, recorded as no override (so the config hash stays that of the default run).
    pub fn set_layout_stream(&mut self, stream: &str) -> Result<(), String> {
        if let Some(problem) = crate::names::variant_name_problem(stream) {
            return Err(format!(
                "invalid `--layout-stream {}`: {problem}\nhint: name a variant whose layouts to share (e.g. `full`), or `{}` for the one stream of clevrtex 0.1",
                crate::text::printable(stream),
                crate::rng::SHARED_STREAM
            ));
        }
        // A stream is a variant's layouts: a name of no variant shares nothing (`nosuch` would
        // silently draw unrelated layouts).
        let known = Config::variant_names();
        if stream != self.name && stream != crate::rng::SHARED_STREAM && !known.contains(&stream) {
            return Err(format!(
                "`--layout-stream {}` names no variant\nhint: name a variant whose layouts to share ({}, or this config's `{}`), or `{}` for the one stream of clevrtex 0.1",
                crate::text::printable(stream),
                known.join(", "),
                crate::text::printable(&self.name),
                crate::rng::SHARED_STREAM
            ));
        }
        self.layout_stream = (stream != self.name).then(|| stream.to_string());
        Ok(())
    }

    /// The config's hash (xxh3 of its debug form, 16 hex digits): a run's `config_hash`,
    /// recorded in its manifest and each sample's metadata, over the config with the command
    /// line's changes and passes applied.
    pub fn content_hash(&self) -> String {
        format!(
            "{:016x}",
            clevrtex_materials::content_hash(&[format!("{self:?}").as_bytes()])
        )
    }

    /// Whether the variant's objects are plain-coloured (its config lists `objects.colors`, as
    /// `vbg` and `clevr` do): their colour is then a property worth scoring by, so `eval` and
    /// the Python `Dataset` break results down and report metadata by colour.
    pub fn colour_breakdown(&self) -> bool {
        !self.objects.colors.is_empty()
    }
}

// ---- file shapes -------------------------------------------------------------------------

/// The name tables of a variant's config, for ids a model can use (the Python `Dataset`'s
/// `names`, the COCO export's categories and attributes): shapes and sizes (with their scale)
/// in the config's order, the materials of objects and ground sorted, the colours (empty when
/// the variant does not colour objects).
#[derive(Debug, Clone, PartialEq)]
pub struct NameTables {
    /// Shape names.
    pub shape: Vec<String>,
    /// Size names with the unit mesh's scale.
    pub size: Vec<(String, f64)>,
    /// Material names of objects and ground, sorted, no duplicates.
    pub material: Vec<String>,
    /// Colour names.
    pub color: Vec<String>,
}

impl Config {
    /// The name tables of this config ([`NameTables`]).
    pub fn name_tables(&self) -> NameTables {
        let mut material: Vec<String> = self.objects.materials.clone();
        material.extend(self.background.materials.iter().cloned());
        material.sort();
        material.dedup();
        NameTables {
            shape: self.objects.shapes.clone(),
            size: self
                .objects
                .sizes
                .iter()
                .map(|s| (s.name.clone(), s.scale))
                .collect(),
            material,
            color: self.objects.colors.iter().map(|c| c.name.clone()).collect(),
        }
    }
}
