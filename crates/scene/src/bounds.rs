//! The one table of numeric bounds, each with its reason, shared by config validation
//! ([`crate::config`]), the sampler's inputs and [`crate::SceneFile::validate`], so that
//! `sample --config` refuses exactly what `render` would refuse, and a hostile scene file
//! never reaches Blender with a value it crashes on or silently clamps.
//!
//! A config's values are bounded so that every scene sampled from it lies within the scene
//! file's bounds: e.g. the placement area (at most [`PLACEMENT_AREA`]) keeps every object
//! within [`crate::scene_file::MAX_OBJECT_DISTANCE_M`] of the origin, and a location (at most
//! [`POSITION`]) plus its jitter (at most [`JITTER`]) stays within the scene file's
//! [`crate::scene_file::MAX_MAGNITUDE`]. The unit test `sampled_scenes_at_the_bounds_validate`
//! checks that. `docs/scene-format.md`, "Bounds", lists the table.

use std::fmt;

/// A closed (or, with `min_exclusive`, half-open) range of one kind of value, with its reason.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Bound {
    /// What the bound is of, in words (for the docs table).
    pub what: &'static str,
    /// Smallest value allowed.
    pub min: f64,
    /// Whether `min` itself is refused (`(min, max]`).
    pub min_exclusive: bool,
    /// Largest value allowed.
    pub max: f64,
    /// Why: what goes wrong outside the range.
    pub reason: &'static str,
}

/// A value outside its [`Bound`]: the key, the value and the rule with its reason.
#[derive(Debug, Clone, PartialEq)]
pub struct OutOfBounds {
    /// Dotted key of the value (`camera.focal_length_mm`, `objects[2].scale`).
    pub key: String,
    /// The value refused.
    pub value: f64,
    /// The rule and its reason.
    pub problem: String,
}

impl fmt::Display for OutOfBounds {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "`{}` = {}: {}", self.key, self.value, self.problem)
    }
}

impl Bound {
    /// The range as text: `1 to 5000`, `more than 0 and at most 10`.
    pub fn range(&self) -> String {
        if self.min_exclusive {
            format!("more than {} and at most {}", self.min, self.max)
        } else {
            format!("{} to {}", self.min, self.max)
        }
    }

    /// Whether `v` is within the bound (NaN never is).
    pub fn contains(&self, v: f64) -> bool {
        let above = if self.min_exclusive {
            v > self.min
        } else {
            v >= self.min
        };
        above && v <= self.max
    }

    /// `v` (the value of `key`) within the bound, or what is wrong.
    pub fn check(&self, key: &str, v: f64) -> Result<(), OutOfBounds> {
        if self.contains(v) {
            return Ok(());
        }
        Err(OutOfBounds {
            key: key.to_string(),
            value: v,
            problem: format!("must be {} ({})", self.range(), self.reason),
        })
    }
}

/// A closed range `[min, max]` of `what`, with its reason.
const fn closed(what: &'static str, min: f64, max: f64, reason: &'static str) -> Bound {
    Bound {
        what,
        min,
        min_exclusive: false,
        max,
        reason,
    }
}

/// Largest index of an image, plus one: 100 million, a hundred times the largest dataset anyone
/// renders. Also the dataset cap of `verify` (`clevrtex_dataset::manifest::MAX_RUN_INDICES`,
/// the most indices a manifest's range or the union of a dataset's runs may hold), so a scene,
/// `sample` or `generate` never makes an index `verify` refuses.
pub const INDEX_END: u64 = 100_000_000;

/// Largest image side accepted anywhere (flags, configs, scene files, and every reader of a
/// dataset, which checks PNG and EXR headers against it): 4096 px. At most 4096x4096 (16.8 M
/// pixels; 4K frames fit) so that a hostile file under 1 MB that declares the largest size
/// decodes in well under 2 GB in every reader (8192x8192 took `materials measure` to 2.8 GB).
pub const MAX_IMAGE_SIDE: u32 = 4096;

// The table's rows, each declared once: a `pub const` (its doc, its name where it is used)
// and a row of [`TABLE`] (the docs table's order); one line a bound: what, range, reason.
macro_rules! table {
    ($($(#[$doc:meta])* $name:ident = $bound:expr;)*) => {
        $($(#[$doc])* pub const $name: Bound = $bound;)*
        /// Every bound, for the docs table and its test.
        pub const TABLE: [&Bound; [$(stringify!($name)),*].len()] = [$(&$name),*];
    };
}

table! {
    /// Image index in a scene file (and `--start`, `--start + -n`, `--total` of `sample` and
    /// `generate`).
    INDEX = closed("image index", 0.0, (INDEX_END - 1) as f64, "a dataset holds at most 100000000 images; `verify` refuses larger indices");
    /// Camera focal length, mm.
    FOCAL_LENGTH_MM = closed("camera focal length, mm", 1.0, 5000.0, "Blender's camera lens is at least 1 mm (0 or less would write zero or null intrinsics); 5000 mm on the 32 mm sensor is a 0.4 degree view that shows nothing of a scene");
    /// Camera sensor width, mm.
    SENSOR_WIDTH_MM = closed("camera sensor width, mm", 1.0, 1000.0, "Blender's sensor is at least 1 mm wide; the reference uses 32 mm");
    /// Any location or look-at coordinate of a config's camera and lights, and the backdrop's
    /// profile and extent, m.
    POSITION = closed("location, look-at and backdrop coordinate, m", -1000.0, 1000.0, "the reference scene fits in 20 m; with its jitter it stays far inside the scene file's magnitude bound");
    /// Camera clip distances, m.
    CLIP_DISTANCE = closed("camera clip_start and clip_end, m", 1e-6, 1e6, "Blender's nearest clip is 1e-6 m; the scene file's magnitude bound is 1e6; the reference uses 0.1 and 100");
    /// Rotation of the backdrop about world z, rad.
    ROTATION_RAD = closed("backdrop rotation about z, rad", -std::f64::consts::TAU, std::f64::consts::TAU, "one turn either way says every rotation; the reference uses 2.698");
    /// Jitter of a camera or light location, m (each coordinate moves by Uniform(-j, j)).
    JITTER = closed("camera and light jitter, m", 0.0, 10.0, "a negative jitter is no range; the reference uses 0.5 and 1 m");
    /// Area-light power, W.
    LIGHT_ENERGY_W = closed("area-light energy, W", 0.0, 1e6, "negative power subtracts light (Cycles renders negative radiance); the reference's key light is 500 W");
    /// Area-light side, m.
    LIGHT_SIZE_M = closed("area-light size, m", 0.0, 100.0, "a negative size is no square; the reference uses 0.2 to 1 m");
    /// Components of a linear RGB colour (lights, objects).
    COLOR = closed("linear RGB colour component", 0.0, 1.0, "a negative component subtracts light; CLEVR's colours and the reference lights lie in 0 to 1");
    /// Sun strength, W/m^2.
    SUN_STRENGTH = closed("sun strength, W/m^2", 0.0, 1e4, "negative strength subtracts light; the reference uses 0.85");
    /// Sun angular diameter, rad.
    SUN_ANGLE = closed("sun angular diameter, rad", 0.0, std::f64::consts::PI, "Blender's sun angle is 0 to 180 degrees");
    /// Points of the backdrop's profile.
    PROFILE_POINTS = closed("backdrop profile points", 2.0, 1024.0, "a profile needs two points; a profile of 60000 points crashed Blender (segfault), and the reference has 9");
    /// Extent of the backdrop along its profile's x and along its y, m.
    BACKDROP_EXTENT = closed("backdrop extent along x and along y, m", 0.0, 200.0, "the bridge meshes the backdrop every 0.2 m along x and 1 m along y, so 200 m by 200 m is at most about 400000 vertices; the reference is 26 m by 38 m");
    /// Scale of an object size, m (the object's radius).
    OBJECT_SCALE = Bound { what: "object scale, m", min: 0.0, min_exclusive: true, max: 10.0, reason: "a scale of 0 or less has no surface; the reference uses 0.4 to 0.9 and its camera sees a 6 m area" };
    /// Displacement strength of a material instance, m.
    DISPLACEMENT = closed("material displacement, m", 0.0, 10.0, "negative displacement turns the surface inside out; the reference uses 0.35");
    /// Texture scale multiplier of a material instance.
    TEXTURE_SCALE = Bound { what: "material texture scale", min: 0.0, min_exclusive: true, max: 1000.0, reason: "0 collapses a texture to one colour; the reference uses 2" };
    /// Per-instance random value of a material.
    MATERIAL_RANDOM = Bound { what: "material random value", min: 0.0, min_exclusive: false, max: 1.0, reason: "the sampler draws it from [0, 1) and recipes read it as such" };
    /// Each end of the placement area, m.
    PLACEMENT_AREA = closed("placement area end, m", -500.0, 500.0, "every object must lie within 1000 m of the origin, as every scene file is checked");
    /// Minimum gap and margin of the placement rules, m.
    PLACEMENT_GAP = closed("placement min_dist and margin, m", 0.0, 100.0, "a negative gap is no rule; the reference uses 0.25 and 0.4");
    /// Position draws per object, and layout restarts.
    PLACEMENT_TRIES = closed("placement tries_per_object and max_restarts", 1.0, 100000.0, "they bound the draws of one image; the reference uses 50 and 1000, `outd` 20000 restarts");
    /// Cycles bounces of each kind.
    BOUNCES = closed("render bounces (each kind)", 0.0, 1024.0, "Blender's range for every bounce count");
    /// Pixel filter width, px.
    FILTER_WIDTH = closed("render filter width, px", 0.01, 10.0, "Blender's range; the reference uses 1.5");
    /// Filter glossy.
    BLUR_GLOSSY = closed("render blur_glossy", 0.0, 10.0, "Blender's range; the reference uses 2");
    /// Indirect clamp.
    CLAMP_INDIRECT = closed("render clamp_indirect", 0.0, 1e8, "Blender's range (0 = off)");
    /// Adaptive-sampling noise threshold.
    ADAPTIVE_THRESHOLD = closed("render adaptive_threshold", 0.0, 1.0, "Blender's range");
    /// View exposure.
    EXPOSURE = closed("render exposure", -32.0, 32.0, "Blender's range; the reference uses 0");
    /// View gamma.
    GAMMA = closed("render gamma", 0.0, 5.0, "Blender's range; the reference uses 1");
    /// Image width and height, px ([`MAX_IMAGE_SIDE`], checked as integers).
    IMAGE_SIDE = closed("render width and height, px", 1.0, MAX_IMAGE_SIDE as f64, "a hostile file declaring the largest size must decode in well under 2 GB in every reader");
}

/// Each coordinate of `v` within `bound` (`key` names the array).
pub fn check_all(bound: &Bound, key: &str, v: &[f64]) -> Result<(), OutOfBounds> {
    for (i, x) in v.iter().enumerate() {
        bound.check(&format!("{key}[{i}]"), *x)?;
    }
    Ok(())
}

/// The backdrop's profile and extent within their bounds (`prefix`: `backdrop` or
/// `base_scene.backdrop`): at most [`PROFILE_POINTS`] points, every coordinate a
/// [`POSITION`], x strictly increasing, the x span and `y_range` (low, high) within
/// [`BACKDROP_EXTENT`].
pub fn check_backdrop(
    prefix: &str,
    profile: &[[f64; 2]],
    y_range: [f64; 2],
) -> Result<(), OutOfBounds> {
    check_count(&PROFILE_POINTS, &format!("{prefix}.profile"), profile.len())?;
    for (i, p) in profile.iter().enumerate() {
        check_all(&POSITION, &format!("{prefix}.profile[{i}]"), p)?;
    }
    check_all(&POSITION, &format!("{prefix}.y_range"), &y_range)?;
    if let Some(i) = profile.windows(2).position(|w| w[0][0] >= w[1][0]) {
        return Err(OutOfBounds {
            key: format!("{prefix}.profile[{}][0]", i + 1),
            value: profile[i + 1][0],
            problem: "x must increase strictly along the profile".into(),
        });
    }
    let span = profile[profile.len() - 1][0] - profile[0][0];
    BACKDROP_EXTENT.check(&format!("{prefix}.profile (x span)"), span)?;
    let y_span = y_range[1] - y_range[0];
    if y_span <= 0.0 {
        return Err(OutOfBounds {
            key: format!("{prefix}.y_range"),
            value: y_span,
            problem: "must be `[low, high]` with low < high".into(),
        });
    }
    BACKDROP_EXTENT.check(&format!("{prefix}.y_range (span)"), y_span)
}

/// A count (number of list entries) within `bound`.
pub fn check_count(bound: &Bound, key: &str, n: usize) -> Result<(), OutOfBounds> {
    bound.check(key, n as f64)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ranges_read_and_refuse_nan() {
        assert_eq!(FOCAL_LENGTH_MM.range(), "1 to 5000");
        assert!(OBJECT_SCALE.range().starts_with("more than 0"));
        assert!(!OBJECT_SCALE.contains(0.0));
        assert!(!LIGHT_ENERGY_W.contains(f64::NAN));
        let e = FOCAL_LENGTH_MM
            .check("camera.focal_length_mm", 0.0)
            .unwrap_err();
        assert!(
            e.to_string()
                .starts_with("`camera.focal_length_mm` = 0: must be 1 to 5000 ("),
            "{e}"
        );
    }

    #[test]
    fn every_bound_has_a_reason_and_a_range() {
        for b in TABLE {
            assert!(b.min <= b.max, "{}", b.what);
            assert!(!b.reason.is_empty() && !b.what.is_empty());
        }
    }

    /// `docs/scene-format.md`, "Bounds", lists the table as it is.
    #[test]
    fn the_docs_list_every_bound() {
        let docs = include_str!("../../../docs/scene-format.md");
        let table: String = TABLE
            .iter()
            .map(|b| format!("| {} | {} | {} |\n", b.what, b.range(), b.reason))
            .collect();
        assert!(
            docs.contains(&table),
            "docs/scene-format.md lacks:\n{table}"
        );
    }

    #[test]
    fn reference_render_settings_are_within_bounds() {
        let c = crate::Config::builtin("full").unwrap();
        crate::scene_file::check_render("render", &c.base.render).unwrap();
    }
}

#[cfg(test)]
mod config_tests {
    use crate::{sample, Config, SampleRequest};

    fn with_base(over: &str) -> String {
        include_str!("../../../configs/full.json").replacen(
            '{',
            &format!(r#"{{"base_scene": {over},"#),
            1,
        )
    }

    /// A config at the edge of every bound the sampler reads still samples scenes that
    /// `render` accepts: config validation and `SceneFile::validate` agree.
    #[test]
    fn sampled_scenes_at_the_bounds_validate() {
        let text = with_base(
            r#"{"camera": {"location": [1000, -1000, 1000], "jitter": 10, "focal_length_mm": 5000, "sensor_width_mm": 1000, "clip_start": 1e-6, "clip_end": 1e6},
                "lights": [{"name": "key", "location": [-1000, 1000, 1000], "look_at": [0, 0, 0], "jitter": 10, "size": 100, "energy": 1e6, "color": [1, 1, 1]}],
                "sun": {"direction": [0, 0, -1], "strength": 1e4, "angle": 3.14159},
                "backdrop": {"profile": [[-100, 0], [100, 1000]], "y_range": [-100, 100], "rotation_z": -6.28},
                "placement": {"area": [-500, 500], "min_dist": 100, "margin": 100, "tries_per_object": 100000, "max_restarts": 2}}"#,
        )
        .replace("\"scale\": 0.9", "\"scale\": 10");
        let c = Config::from_json_str(&text, "edge.json").unwrap();
        for index in 0..5 {
            let req = SampleRequest {
                seed: 1,
                index,
                attempt: 0,
                total: 5,
            };
            if let Ok(s) = sample(&c, &req) {
                s.validate().unwrap_or_else(|e| panic!("{index}: {e}"));
            }
        }
    }

    /// What `render` would refuse, `sample --config` refuses first (issue 34: scales,
    /// displacements and jitters of 1e300 were sampled, then refused by `render`).
    #[test]
    fn config_refuses_what_render_would() {
        for (over, key) in [
            (
                r#"{"camera": {"jitter": 1e300}}"#,
                "base_scene.camera.jitter",
            ),
            (
                r#"{"camera": {"focal_length_mm": 0.5}}"#,
                "base_scene.camera.focal_length_mm",
            ),
            (
                r#"{"lights": [{"name": "key", "location": [1, 1, 1], "look_at": [0, 0, 0], "jitter": 1, "size": 1, "energy": -5, "color": [1, 1, 1]}]}"#,
                "base_scene.lights[0].energy",
            ),
            (
                r#"{"backdrop": {"profile": [[0, 0], [1e5, 0]]}}"#,
                "base_scene.backdrop.profile[1][0]",
            ),
            (
                r#"{"placement": {"area": [-1e300, 1e300]}}"#,
                "base_scene.placement.area[0]",
            ),
            (r#"{"render": {"gamma": -1}}"#, "base_scene.render.gamma"),
            (
                r#"{"sun": {"direction": [0, 0, 0]}}"#,
                "base_scene.sun.direction",
            ),
        ] {
            let e = Config::from_json_str(&with_base(over), "x.json").unwrap_err();
            assert_eq!(e.key, key, "{over}: {e}");
            assert!(e.to_string().contains("\nhint: "), "{e}");
        }
        let full = include_str!("../../../configs/full.json");
        for (from, to, key) in [
            (
                "\"scale\": 0.9",
                "\"scale\": 1e300",
                "objects.sizes[0].scale",
            ),
            ("\"scale\": 2.0", "\"scale\": 1e300", "background.scale"),
        ] {
            let text = full.replacen(from, to, 1);
            assert_ne!(text, full, "{from}");
            let e = Config::from_json_str(&text, "x.json").unwrap_err();
            assert_eq!(e.key, key, "{e}");
        }
    }
}
