//! The metadata file of a rendered sample: every key of the published dataset (from
//! [`clevrtex_scene::metadata()`]) plus ours (seed, attempt, camera matrices, visibility per
//! object, pass encodings, render settings, versions).

use clevrtex_scene::{Pass, SceneFile};
use serde_json::{json, Value};

use crate::post::{self, ObjectPixels};

/// Facts about the render that only exist after it ran.
#[derive(Debug, Clone)]
pub struct RenderFacts {
    /// Visible pixels and 2D box per object, from the final mask.
    pub objects: Vec<ObjectPixels>,
    /// Blender's version string (from the worker's `ready`).
    pub blender_version: String,
    /// Passes actually written (the scene's request).
    pub passes: Vec<Pass>,
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

/// How each pass is encoded: written into every metadata file.
pub fn pass_encodings(passes: &[Pass]) -> Value {
    let mut map = serde_json::Map::new();
    for &p in passes {
        let v = match p {
            Pass::Rgb => json!({"format": "png", "bits": 8, "channels": "RGB",
                "encoding": "colour-managed render (view transform and look of `render`), sRGB"}),
            Pass::Mask => json!({"format": "png", "bits": 8, "channels": "palette index",
                "encoding": "instance id: 0 = background, i = objects[i-1]; exact object-index pass, never anti-aliased"}),
            Pass::Depth => json!({"format": "png", "bits": 16, "channels": "gray",
                "encoding": "planar depth (distance along the camera's view axis, metres) = value * scale",
                "scale": post::DEPTH_SCALE_M, "background": post::DEPTH_BACKGROUND}),
            Pass::Normal => json!({"format": "png", "bits": 16, "channels": "RGB = XYZ",
                "space": "world", "encoding": "n = value / 65535 * 2 - 1",
                "background": [32768, 32768, 32768]}),
            Pass::Albedo => json!({"format": "png", "bits": 8, "channels": "RGB",
                "encoding": "diffuse colour pass, linear values encoded with the sRGB transfer curve"}),
            Pass::Shadow => json!({"format": "png", "bits": 8, "channels": "gray",
                "encoding": "shadow = value / 255 = 1 - direct diffuse light / the same with objects casting no shadows (luminance)",
                "undefined": post::SHADOW_UNDEFINED,
                "undefined_when": format!("unshadowed direct light luminance < {}", post::SHADOW_EPS)}),
        };
        map.insert(p.name().to_string(), v);
    }
    Value::Object(map)
}

/// The full metadata document of a rendered scene.
pub fn build(scene: &SceneFile, facts: &RenderFacts) -> Value {
    let mut shown = scene.clone();
    shown.passes = facts.passes.clone();
    let base = clevrtex_scene::metadata(&shown);
    let mut doc = serde_json::to_value(&base).expect("metadata serialises");
    let threshold = post::visibility_threshold(scene.render.width, scene.render.height);
    if let Some(objects) = doc.get_mut("objects").and_then(Value::as_array_mut) {
        for (o, px) in objects.iter_mut().zip(&facts.objects) {
            if let Some(o) = o.as_object_mut() {
                o.insert("visible_pixels".into(), json!(px.pixels));
                o.insert("bbox".into(), json!(px.bbox));
            }
        }
    }
    let obj = doc.as_object_mut().expect("metadata is an object");
    // Reference loaders read every `*_filename` key: unrequested passes are `null`.
    for key in [
        "image_filename",
        "mask_filename",
        "normal_filename",
        "albedo_filename",
        "depth_filename",
        "shadow_filename",
    ] {
        obj.entry(key).or_insert(Value::Null);
    }
    obj.insert("variant".into(), json!(scene.variant));
    obj.insert("stem".into(), json!(scene.stem));
    obj.insert("seed".into(), json!(scene.seed));
    obj.insert("attempt".into(), json!(scene.attempt));
    obj.insert(
        "camera".into(),
        json!({
            "intrinsics": intrinsics(scene),
            "extrinsics": extrinsics_opencv(scene),
            "extrinsics_convention": "world to camera, OpenCV axes (x right, y down, z forward); pixel = K * (E * X) / z, origin at the top-left image corner",
            "matrix_world": scene.camera.matrix_world,
            "matrix_world_convention": "camera to world, Blender axes (x right, y up, looking along -z)",
            "focal_length_mm": scene.camera.focal_length_mm,
            "sensor_width_mm": scene.camera.sensor_width_mm,
            "sensor_fit": "AUTO",
            "clip": [scene.camera.clip_start, scene.camera.clip_end],
        }),
    );
    obj.insert("visibility_threshold_px".into(), json!(threshold));
    obj.insert("passes".into(), pass_encodings(&facts.passes));
    obj.insert(
        "render".into(),
        serde_json::to_value(&scene.render).expect("serialises"),
    );
    obj.insert("blender_version".into(), json!(facts.blender_version));
    obj.insert("clevrtex_version".into(), json!(env!("CARGO_PKG_VERSION")));
    doc
}
