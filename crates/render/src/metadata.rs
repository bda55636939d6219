//! The metadata file of a rendered sample: every key of the published dataset (from
//! [`clevrtex_scene::metadata()`]) plus ours (seed, attempt, camera matrices, visibility per
//! object, pass encodings, render settings, versions).

use std::collections::BTreeMap;

use clevrtex_scene::metadata::Visibility;
use clevrtex_scene::passes::Encoding;
use clevrtex_scene::scene_file::RenderSettings;
use clevrtex_scene::{ClevrMetadata, Pass, SceneFile};
use serde::Serialize;

use crate::post::{self, ObjectPixels};

/// Facts about the render that only exist after it ran.
#[derive(Debug, Clone)]
pub struct RenderFacts<'a> {
    /// Visible pixels and 2D box per object, from the final mask.
    pub objects: Vec<ObjectPixels>,
    /// Blender's version string (from the worker's `ready`).
    pub blender_version: String,
    /// The bridge's version-parity settings (the worker's `ready.compat`).
    pub blender_compat: BTreeMap<String, serde_json::Value>,
    /// Passes actually written (the scene's request).
    pub passes: Vec<Pass>,
    /// The run's user materials, name -> content hash; those the scene uses are recorded.
    pub user_materials: &'a BTreeMap<String, String>,
    /// The run's config hash (`generate`'s manifest `config_hash`); `None` for `render`.
    pub config_hash: Option<&'a str>,
}

/// Camera intrinsics `K` (pixels, origin at the top-left corner, y down, principal point at
/// the centre; Blender's sensor fit `AUTO`).
pub fn intrinsics(scene: &SceneFile) -> [[f64; 3]; 3] {
    let (w, h) = (scene.render.width, scene.render.height);
    let f = clevrtex_scene::camera::focal_px(&scene.camera, w, h);
    [
        [f, 0.0, w as f64 / 2.0],
        [0.0, f, h as f64 / 2.0],
        [0.0, 0.0, 1.0],
    ]
}

/// World-to-camera extrinsics in the OpenCV convention (x right, y down, z forward), so that
/// `K * (E * [X, 1])` divided by its z gives the same pixel coordinates as `pixel_coords`.
pub fn extrinsics_opencv(scene: &SceneFile) -> [[f64; 4]; 4] {
    let m = &scene.camera.matrix_world;
    let t = [m[0][3], m[1][3], m[2][3]];
    // Blender camera axes are the columns of m: right, up, backward. OpenCV: right, down, forward.
    let axes = [
        [m[0][0], m[1][0], m[2][0]],
        [-m[0][1], -m[1][1], -m[2][1]],
        [-m[0][2], -m[1][2], -m[2][2]],
    ];
    let mut e = [[0.0; 4]; 4];
    for (r, a) in axes.iter().enumerate() {
        e[r][..3].copy_from_slice(a);
        e[r][3] = -(a[0] * t[0] + a[1] * t[1] + a[2] * t[2]);
    }
    e[3][3] = 1.0;
    e
}

/// The camera, in both conventions (`camera` of the metadata).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct CameraMetadata {
    /// Intrinsics `K`, see [`intrinsics`].
    pub intrinsics: [[f64; 3]; 3],
    /// World to camera, OpenCV axes, see [`extrinsics_opencv`].
    pub extrinsics: [[f64; 4]; 4],
    /// How to read `extrinsics`.
    pub extrinsics_convention: &'static str,
    /// Camera to world, Blender axes (the scene file's matrix).
    pub matrix_world: [[f64; 4]; 4],
    /// How to read `matrix_world`.
    pub matrix_world_convention: &'static str,
    /// Focal length.
    pub focal_length_mm: f64,
    /// Sensor width.
    pub sensor_width_mm: f64,
    /// Blender's sensor fit.
    pub sensor_fit: &'static str,
    /// Clip start and end.
    pub clip: [f64; 2],
}

/// The metadata file of a rendered sample: every key of the published dataset (the
/// flattened [`ClevrMetadata`], with each object's visibility) plus ours.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct SampleMetadata {
    /// The published keys.
    #[serde(flatten)]
    pub clevr: ClevrMetadata,
    /// Variant name.
    pub variant: String,
    /// File stem.
    pub stem: String,
    /// Run seed.
    pub seed: u64,
    /// The layout stream of the draws (the scene file's `layout_stream`: the variant's name
    /// unless `--layout-stream` chose another).
    pub layout_stream: String,
    /// The config hash of the `generate` run that made the sample (its manifest's
    /// `config_hash`), so `verify` can tell a sample made from another config; absent from
    /// `render` and in older datasets.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub config_hash: Option<String>,
    /// Accepted layout attempt.
    pub attempt: u32,
    /// The camera.
    pub camera: CameraMetadata,
    /// Objects at or under this many visible pixels were rejected.
    pub visibility_threshold_px: u64,
    /// How each written pass is encoded, by pass name (from the pass table).
    pub passes: BTreeMap<&'static str, Encoding>,
    /// The render settings.
    pub render: RenderSettings,
    /// Blender's version string.
    pub blender_version: String,
    /// The settings the bridge changed on this Blender to render as 3.4 does
    /// (`compat.parity_settings()`, e.g. `{"coat": true, ...}` on 4.x); absent on 3.x.
    #[serde(skip_serializing_if = "BTreeMap::is_empty")]
    pub blender_compat: BTreeMap<String, serde_json::Value>,
    /// This tool's version.
    pub clevrtex_version: &'static str,
    /// The user materials (`--materials DIR`) of the scene: name -> content hash of the
    /// `.blend` (or material file) and every image it reads; absent with built-ins only.
    #[serde(skip_serializing_if = "BTreeMap::is_empty")]
    pub user_materials: BTreeMap<String, String>,
}

impl SampleMetadata {
    /// The file's text: pretty JSON with every object's keys sorted (a canonical form, so
    /// equal metadata is equal bytes).
    pub fn to_json_pretty(&self) -> String {
        let value = serde_json::to_value(self).expect("metadata serialises");
        serde_json::to_string_pretty(&value).expect("metadata serialises")
    }
}

/// The full metadata of a rendered scene.
pub fn build(scene: &SceneFile, facts: &RenderFacts<'_>) -> SampleMetadata {
    let mut shown = scene.clone();
    shown.passes = facts.passes.clone();
    let mut clevr = clevrtex_scene::metadata(&shown);
    for (o, px) in clevr.objects.iter_mut().zip(&facts.objects) {
        o.visibility = Some(Visibility {
            visible_pixels: px.pixels,
            bbox: px.bbox,
        });
    }
    let cam = &scene.camera;
    SampleMetadata {
        clevr,
        variant: scene.variant.clone(),
        stem: scene.stem.clone(),
        seed: scene.seed,
        layout_stream: scene.layout_stream.clone(),
        config_hash: facts.config_hash.map(str::to_string),
        attempt: scene.attempt,
        camera: CameraMetadata {
            intrinsics: intrinsics(scene),
            extrinsics: extrinsics_opencv(scene),
            extrinsics_convention: "world to camera, OpenCV axes (x right, y down, z forward); pixel = K * (E * X) / z, origin at the top-left image corner",
            matrix_world: cam.matrix_world,
            matrix_world_convention: "camera to world, Blender axes (x right, y up, looking along -z)",
            focal_length_mm: cam.focal_length_mm,
            sensor_width_mm: cam.sensor_width_mm,
            sensor_fit: "AUTO",
            clip: [cam.clip_start, cam.clip_end],
        },
        visibility_threshold_px: post::visibility_threshold(scene.render.width, scene.render.height),
        passes: facts.passes.iter().map(|p| (p.name(), p.spec().encoding)).collect(),
        render: scene.render.clone(),
        blender_version: facts.blender_version.clone(),
        blender_compat: facts.blender_compat.clone(),
        clevrtex_version: env!("CARGO_PKG_VERSION"),
        user_materials: std::iter::once(&scene.backdrop.material)
            .chain(scene.objects.iter().map(|o| &o.material))
            .filter_map(|m| {
                let hash = facts.user_materials.get(&m.name)?;
                Some((m.name.clone(), hash.clone()))
            })
            .collect(),
    }
}
