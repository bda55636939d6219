//! The scene file: the contract between the Rust sampler and the Blender bridge.
//!
//! A scene file holds everything the bridge needs to build one image with no randomness of
//! its own, and nothing it does not need. Every position, rotation and matrix here is final:
//! the bridge copies them into Blender, it never derives or jitters. See
//! `docs/scene-format.md` for the field-by-field description.

use serde::{Deserialize, Serialize};

use crate::bounds::{self, OutOfBounds};

pub use crate::passes::Pass;

/// Value of [`SceneFile::format`]: lets tools recognise a scene file.
pub const SCENE_FORMAT: &str = "clevrtex-scene";
/// Current value of [`SceneFile::version`]. Bump on any incompatible change.
pub const SCENE_VERSION: u32 = 1;

/// One image's scene, as written by `clevrtex sample` and read by the bridge.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SceneFile {
    /// Always [`SCENE_FORMAT`].
    pub format: String,
    /// Always [`SCENE_VERSION`] for files this version writes.
    pub version: u32,
    /// Variant name (`full`, `pbg`, `vbg`, `grassbg`, `camo`, `outd`, `clevr` or a user config's name).
    pub variant: String,
    /// Image index within the run (the number in the file stem).
    pub index: u64,
    /// `test`, `val` or `train`, from the index and the run size.
    pub split: String,
    /// Run seed. Together with `layout_stream`, `index` and `attempt` it fixes every random
    /// draw.
    pub seed: u64,
    /// The layout stream the draws came from: the variant's name unless `--layout-stream`
    /// chose another (`shared`: clevrtex 0.1's one stream, also what a file without the key
    /// was drawn from).
    #[serde(default = "shared_stream")]
    pub layout_stream: String,
    /// Visibility retry number: 0 for the first layout, +1 for each rejected one.
    pub attempt: u32,
    /// File stem shared by every output of this image, e.g. `CLEVRTEX_camo_000012`.
    pub stem: String,
    /// Render settings.
    pub render: RenderSettings,
    /// Passes to produce, in canonical order (a subset of [`Pass::ALL`]).
    pub passes: Vec<Pass>,
    /// The camera, fully posed.
    pub camera: Camera,
    /// Area lights (key, fill, back), fully posed.
    pub lights: Vec<AreaLight>,
    /// The sun.
    pub sun: Sun,
    /// The studio backdrop and its material.
    pub backdrop: Backdrop,
    /// Objects in metadata order: object `i` gets instance id `i + 1` in the mask.
    pub objects: Vec<SceneObject>,
}

fn shared_stream() -> String {
    crate::rng::SHARED_STREAM.to_string()
}

/// Cycles and colour-management settings.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RenderSettings {
    /// Image width in pixels.
    pub width: u32,
    /// Image height in pixels.
    pub height: u32,
    /// Samples per pixel.
    pub samples: u32,
    /// Adaptive-sampling noise threshold; `None` turns adaptive sampling off.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub adaptive_threshold: Option<f32>,
    /// Total max bounces.
    pub max_bounces: u32,
    /// Diffuse bounces.
    pub diffuse_bounces: u32,
    /// Glossy bounces.
    pub glossy_bounces: u32,
    /// Transmission bounces.
    pub transmission_bounces: u32,
    /// Transparent bounces.
    pub transparent_max_bounces: u32,
    /// Indirect light clamp (0 = off).
    #[serde(default)]
    pub clamp_indirect: f32,
    /// Pixel filter width in pixels (Blackman-Harris).
    pub filter_width: f32,
    /// Filter glossy ("blur glossy").
    pub blur_glossy: f32,
    /// Colour-management view transform, e.g. `Filmic`.
    pub view_transform: String,
    /// Colour-management look, e.g. `Very High Contrast` (Blender 3.x spelling, without the
    /// view prefix; the bridge's compat module adapts it).
    pub look: String,
    /// Exposure.
    pub exposure: f32,
    /// Gamma.
    pub gamma: f32,
    /// Cycles sampling seed (absent = 0). Renders of one scene with the same seed share
    /// their first samples, so their noise is correlated: `clevrtex bench` renders its
    /// references with another seed.
    #[serde(default, skip_serializing_if = "is_zero")]
    pub cycles_seed: u32,
    /// Cycles 4.0+'s light tree (absent: the bridge's default for the version; 3.4 has none
    /// and ignores it). See `docs/performance.md`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub light_tree: Option<bool>,
    /// Path guiding (Cycles 3.4+ builds with it, CPU only; Debian's 3.4.1 lacks it and
    /// ignores it).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub path_guiding: Option<bool>,
    /// Blue-noise sampling pattern (4.2+): `true` blue noise, `false` tabulated Sobol; absent:
    /// the version's default.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub blue_noise: Option<bool>,
    /// Denoise the RGB with OpenImageDenoise (opt-in; never the mask, depth, normal or
    /// albedo passes, which Cycles does not denoise). Ignored where the build lacks OIDN.
    #[serde(default, skip_serializing_if = "is_false")]
    pub denoise: bool,
    /// Samples of the shadow pass's render (absent: three eighths of `samples`, at most 64).
    /// The pass's RMSE falls with it (0.018 at 8, 0.010 at 16, 0.008 at 24) and its cost
    /// grows with it (`docs/performance.md`, "Shadow pass").
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub shadow_samples: Option<u32>,
}

fn is_zero(v: &u32) -> bool {
    *v == 0
}

fn is_false(v: &bool) -> bool {
    !*v
}

/// A perspective camera. `matrix_world` is authoritative; the other pose fields restate it.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Camera {
    /// World position.
    pub location: [f64; 3],
    /// Point the camera looks at (its -Z axis points there, +Y up as Blender's track-to).
    pub look_at: [f64; 3],
    /// Row-major 4x4 camera-to-world matrix (columns: right, up, backward, position).
    pub matrix_world: [[f64; 4]; 4],
    /// Focal length in millimetres.
    pub focal_length_mm: f64,
    /// Sensor width in millimetres (sensor fit `AUTO`).
    pub sensor_width_mm: f64,
    /// Near clip distance.
    pub clip_start: f64,
    /// Far clip distance.
    pub clip_end: f64,
}

/// A square area light aimed at a point.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct AreaLight {
    /// `key`, `fill` or `back`.
    pub name: String,
    /// World position (jitter already applied).
    pub location: [f64; 3],
    /// Row-major 4x4 light-to-world matrix; the light emits along its local -Z.
    pub matrix_world: [[f64; 4]; 4],
    /// Side of the square, metres.
    pub size: f64,
    /// Power in watts.
    pub energy: f64,
    /// Linear RGB colour.
    pub color: [f64; 3],
}

/// The sun lamp.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Sun {
    /// Unit vector the light travels along.
    pub direction: [f64; 3],
    /// Row-major 4x4 sun-to-world matrix (local -Z = `direction`).
    pub matrix_world: [[f64; 4]; 4],
    /// Strength (irradiance, W/m^2).
    pub strength: f64,
    /// Angular diameter in radians.
    pub angle: f64,
}

/// The curved photo-studio backdrop.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Backdrop {
    /// Profile in the backdrop's own frame: `[x, height]` pairs, x increasing; the surface is
    /// this profile swept along y, smoothly interpolated between the points.
    pub profile: Vec<[f64; 2]>,
    /// Extent along the backdrop's own y axis `[min, max]`.
    pub y_range: [f64; 2],
    /// Rotation of the backdrop frame about world z, radians.
    pub rotation_z: f64,
    /// Material of the backdrop.
    pub material: MaterialInstance,
}

/// One object.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SceneObject {
    /// Shape name: `cube`, `sphere`, `cylinder`, `monkey`, `cone`, `torus`, `icosahedron`, `teapot`.
    pub shape: String,
    /// Size name: `large`, `medium`, `small`.
    pub size: String,
    /// Uniform scale applied to the mesh normalised to [-1, 1]^3.
    pub scale: f64,
    /// World position of the object's origin (z = scale: it rests on the floor).
    pub location: [f64; 3],
    /// Rotation about world z, degrees.
    pub rotation_deg: f64,
    /// Material of the object.
    pub material: MaterialInstance,
}

/// A material with its per-instance parameters.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct MaterialInstance {
    /// Catalogue name.
    pub name: String,
    /// Per-instance random value in [0, 1) that varies the look.
    pub random: f64,
    /// Colour name, only in variants that use colours (`vbg`, `clevr`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub color_name: Option<String>,
    /// Linear RGB colour, present exactly when `color_name` is.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub color: Option<[f64; 3]>,
    /// Displacement strength, only where the instance displaces (e.g. backgrounds: 0.35).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub displacement: Option<f64>,
    /// Texture scale multiplier, only where set (e.g. backgrounds: 2).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub scale: Option<f64>,
}

/// Largest image side accepted anywhere (in the one table of bounds, [`bounds::MAX_IMAGE_SIDE`]).
pub use crate::bounds::MAX_IMAGE_SIDE;
/// Most samples per pixel accepted.
pub const MAX_SAMPLES: u32 = 1 << 16;
/// Most objects in a scene: instance ids `1..=N` must fit the 8-bit mask.
pub const MAX_OBJECTS: usize = 255;
/// Largest magnitude of any real number in a scene file (positions, sizes, energies...).
pub const MAX_MAGNITUDE: f64 = 1e6;
/// Farthest an object may be from the world origin, in metres.
pub const MAX_OBJECT_DISTANCE_M: f64 = 1000.0;

impl SceneFile {
    /// Check what the bridge cannot check cheaply, before a scene is sent to Blender: the
    /// format and version, `variant`, `stem` and `split` (the names that become paths: one
    /// plain component each, the stem the layout's own), image size and samples within bounds, every real number finite and
    /// of sane magnitude, at most [`MAX_OBJECTS`] objects, each with a positive scale and near
    /// the origin. The error names the key (`objects[2].location[0]`), its value and the rule.
    pub fn validate(&self) -> Result<(), String> {
        if self.format != SCENE_FORMAT || self.version != SCENE_VERSION {
            return Err(format!(
                "not a version {SCENE_VERSION} clevrtex scene file (format `{}`, version {})",
                self.format, self.version
            ));
        }
        // Names that become paths: one plain component each, checked here so that no value of
        // a scene file ever names a folder outside the output (docs/security.md).
        if let Some(problem) = crate::names::variant_name_problem(&self.variant) {
            return Err(format!("`variant` = {:?}: {problem}", self.variant));
        }
        if let Some(problem) = crate::names::variant_name_problem(&self.layout_stream) {
            return Err(format!(
                "`layout_stream` = {:?}: {problem}",
                self.layout_stream
            ));
        }
        let stem = crate::names::stem(&self.variant, self.index);
        if self.stem != stem {
            return Err(format!(
                "`stem` = {:?}: must be `{stem}` (`CLEVRTEX_<variant>_<index:06>`; it names the sample's files)",
                self.stem
            ));
        }
        if crate::names::Split::parse(&self.split).is_none() {
            return Err(format!(
                "`split` = {:?}: must be `train`, `val` or `test`",
                self.split
            ));
        }
        let r = &self.render;
        for (key, v, max) in [
            ("render.width", r.width, MAX_IMAGE_SIDE),
            ("render.height", r.height, MAX_IMAGE_SIDE),
            ("render.samples", r.samples, MAX_SAMPLES),
            (
                "render.shadow_samples",
                r.shadow_samples.unwrap_or(1),
                MAX_SAMPLES,
            ),
        ] {
            if v == 0 || v > max {
                return Err(format!("`{key}` = {v}: must be between 1 and {max}"));
            }
        }
        if self.objects.len() > MAX_OBJECTS {
            return Err(format!(
                "`objects` has {} entries: at most {MAX_OBJECTS} fit the 8-bit instance mask",
                self.objects.len()
            ));
        }
        let value = serde_json::to_value(self).map_err(|e| e.to_string())?;
        check_numbers(&value, &mut String::new())?;
        self.check_bounds().map_err(|e| e.to_string())?;
        let mut seen = Vec::with_capacity(self.passes.len());
        for p in &self.passes {
            if seen.contains(p) {
                return Err(format!(
                    "`passes` names `{}` twice: each pass is one file of the sample",
                    p.name()
                ));
            }
            seen.push(*p);
        }
        for (i, o) in self.objects.iter().enumerate() {
            if !crate::names::KNOWN_SHAPES.contains(&o.shape.as_str()) {
                return Err(format!(
                    "`objects[{i}].shape` = {:?}: unknown shape (the bridge builds {})",
                    o.shape,
                    crate::names::KNOWN_SHAPES.join(", ")
                ));
            }
        }
        for (i, o) in self.objects.iter().enumerate() {
            let d = o.location.iter().map(|c| c * c).sum::<f64>().sqrt();
            if d > MAX_OBJECT_DISTANCE_M {
                return Err(format!(
                    "`objects[{i}].location` = {:?}: {d:.3e} m from the origin, more than {MAX_OBJECT_DISTANCE_M} m (the camera could never see it)",
                    o.location
                ));
            }
        }
        if !(self.camera.clip_start > 0.0 && self.camera.clip_end > self.camera.clip_start) {
            return Err(format!(
                "`camera.clip_start`/`clip_end` = {}/{}: need 0 < clip_start < clip_end",
                self.camera.clip_start, self.camera.clip_end
            ));
        }
        Ok(())
    }
}

impl SceneFile {
    /// Every value of the scene within the one table of bounds ([`crate::bounds`]).
    fn check_bounds(&self) -> Result<(), OutOfBounds> {
        bounds::INDEX.check("index", self.index as f64)?;
        check_render("render", &self.render)?;
        let c = &self.camera;
        bounds::FOCAL_LENGTH_MM.check("camera.focal_length_mm", c.focal_length_mm)?;
        bounds::SENSOR_WIDTH_MM.check("camera.sensor_width_mm", c.sensor_width_mm)?;
        bounds::CLIP_DISTANCE.check("camera.clip_start", c.clip_start)?;
        bounds::CLIP_DISTANCE.check("camera.clip_end", c.clip_end)?;
        for (i, l) in self.lights.iter().enumerate() {
            bounds::LIGHT_ENERGY_W.check(&format!("lights[{i}].energy"), l.energy)?;
            bounds::LIGHT_SIZE_M.check(&format!("lights[{i}].size"), l.size)?;
            bounds::check_all(&bounds::COLOR, &format!("lights[{i}].color"), &l.color)?;
        }
        bounds::SUN_STRENGTH.check("sun.strength", self.sun.strength)?;
        bounds::SUN_ANGLE.check("sun.angle", self.sun.angle)?;
        let b = &self.backdrop;
        bounds::check_backdrop("backdrop", &b.profile, b.y_range)?;
        bounds::ROTATION_RAD.check("backdrop.rotation_z", b.rotation_z)?;
        b.material.check_bounds("backdrop.material")?;
        for (i, o) in self.objects.iter().enumerate() {
            bounds::OBJECT_SCALE.check(&format!("objects[{i}].scale"), o.scale)?;
            o.material.check_bounds(&format!("objects[{i}].material"))?;
        }
        Ok(())
    }
}

impl MaterialInstance {
    fn check_bounds(&self, key: &str) -> Result<(), OutOfBounds> {
        bounds::MATERIAL_RANDOM.check(&format!("{key}.random"), self.random)?;
        if let Some(c) = &self.color {
            bounds::check_all(&bounds::COLOR, &format!("{key}.color"), c)?;
        }
        if let Some(d) = self.displacement {
            bounds::DISPLACEMENT.check(&format!("{key}.displacement"), d)?;
        }
        if let Some(s) = self.scale {
            bounds::TEXTURE_SCALE.check(&format!("{key}.scale"), s)?;
        }
        Ok(())
    }
}

/// Every real number under `v` finite and at most [`MAX_MAGNITUDE`]; `path` is the key so far.
fn check_numbers(v: &serde_json::Value, path: &mut String) -> Result<(), String> {
    use serde_json::Value;
    match v {
        Value::Number(n) if n.is_f64() => {
            let x = n.as_f64().unwrap_or(f64::NAN);
            if !x.is_finite() || x.abs() > MAX_MAGNITUDE {
                return Err(format!(
                    "`{path}` = {x:e}: numbers must be finite and at most {MAX_MAGNITUDE:e} in magnitude"
                ));
            }
        }
        Value::Array(items) => {
            for (i, item) in items.iter().enumerate() {
                let len = path.len();
                path.push_str(&format!("[{i}]"));
                check_numbers(item, path)?;
                path.truncate(len);
            }
        }
        Value::Object(map) => {
            for (k, item) in map {
                let len = path.len();
                if !path.is_empty() {
                    path.push('.');
                }
                path.push_str(k);
                check_numbers(item, path)?;
                path.truncate(len);
            }
        }
        _ => {}
    }
    Ok(())
}

/// The render settings' real numbers within their bounds ([`crate::bounds`]) (`prefix` is the key's start,
/// `render` in a scene file, `base_scene.render` in a config). Width, height and samples are
/// checked by their callers with their own messages.
pub fn check_render(prefix: &str, r: &RenderSettings) -> Result<(), OutOfBounds> {
    let key = |k: &str| format!("{prefix}.{k}");
    for (k, v) in [
        ("max_bounces", r.max_bounces),
        ("diffuse_bounces", r.diffuse_bounces),
        ("glossy_bounces", r.glossy_bounces),
        ("transmission_bounces", r.transmission_bounces),
        ("transparent_max_bounces", r.transparent_max_bounces),
    ] {
        bounds::BOUNCES.check(&key(k), f64::from(v))?;
    }
    bounds::FILTER_WIDTH.check(&key("filter_width"), f64::from(r.filter_width))?;
    bounds::BLUR_GLOSSY.check(&key("blur_glossy"), f64::from(r.blur_glossy))?;
    bounds::CLAMP_INDIRECT.check(&key("clamp_indirect"), f64::from(r.clamp_indirect))?;
    if let Some(t) = r.adaptive_threshold {
        bounds::ADAPTIVE_THRESHOLD.check(&key("adaptive_threshold"), f64::from(t))?;
    }
    bounds::EXPOSURE.check(&key("exposure"), f64::from(r.exposure))?;
    bounds::GAMMA.check(&key("gamma"), f64::from(r.gamma))?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::{sample, Config, SampleRequest};

    fn scene() -> SceneFile {
        let c = Config::builtin("full").unwrap();
        let req = SampleRequest {
            seed: 3,
            index: 4,
            attempt: 0,
            total: 10,
        };
        let s = sample(&c, &req).unwrap();
        s.validate().unwrap();
        s
    }

    /// Each hostile value is refused with its key (issue 34: all of these reached Blender).
    #[test]
    fn extreme_values_are_refused_naming_the_key() {
        type Break = Box<dyn Fn(&mut SceneFile)>;
        let cases: Vec<(&str, Break)> = vec![
            (
                "camera.focal_length_mm",
                Box::new(|s| s.camera.focal_length_mm = 0.0),
            ),
            (
                "camera.focal_length_mm",
                Box::new(|s| s.camera.focal_length_mm = -35.0),
            ),
            (
                "camera.sensor_width_mm",
                Box::new(|s| s.camera.sensor_width_mm = 0.0),
            ),
            (
                "objects[0].shape",
                Box::new(|s| s.objects[0].shape = "donut".into()),
            ),
            (
                "lights[1].energy",
                Box::new(|s| s.lights[1].energy = -200.0),
            ),
            ("sun.strength", Box::new(|s| s.sun.strength = -1.0)),
            (
                "backdrop.profile",
                Box::new(|s| {
                    s.backdrop.profile = (0..60_000).map(|i| [i as f64 * 1e-3, 0.0]).collect()
                }),
            ),
            (
                "backdrop.y_range",
                Box::new(|s| s.backdrop.y_range = [-600.0, 600.0]),
            ),
            (
                "index",
                Box::new(|s| {
                    s.index = 100_000_000;
                    s.stem = crate::stem(&s.variant, s.index);
                }),
            ),
            (
                "objects[0].material.displacement",
                Box::new(|s| s.objects[0].material.displacement = Some(-1.0)),
            ),
            ("render.exposure", Box::new(|s| s.render.exposure = 100.0)),
            (
                "passes",
                Box::new(|s| s.passes = vec![Pass::Rgb, Pass::Rgb, Pass::Mask]),
            ),
        ];
        for (key, break_it) in cases {
            let mut s = scene();
            break_it(&mut s);
            let e = s.validate().unwrap_err();
            assert!(e.starts_with(&format!("`{key}")), "{key}: {e}");
        }
    }
}
