//! CLEVR-style metadata (`<stem>.json` of a published sample), computed from a scene file.

use serde::Serialize;

pub use crate::camera::Directions;
use crate::camera::{directions, dot, project};
use crate::names;
use crate::scene_file::{Pass, SceneFile};

/// Threshold of the relationships: `j` is `behind` `i` when
/// `dot(pos_j - pos_i, behind) > RELATION_EPS`.
pub const RELATION_EPS: f64 = 0.2;

/// For each relation and each object `i`, the sorted 0-based indices `j` in that relation.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Relationships {
    /// Objects behind object `i`.
    pub behind: Vec<Vec<usize>>,
    /// Objects in front of object `i`.
    pub front: Vec<Vec<usize>>,
    /// Objects left of object `i`.
    pub left: Vec<Vec<usize>>,
    /// Objects right of object `i`.
    pub right: Vec<Vec<usize>>,
}

/// One object's metadata.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct ObjectMetadata {
    /// Shape name.
    pub shape: String,
    /// Rotation about z, degrees.
    pub rotation: f64,
    /// Size name.
    pub size: String,
    /// World position.
    #[serde(rename = "3d_coords")]
    pub coords_3d: [f64; 3],
    /// `[x, y, depth]` of the origin: pixels (y down, not rounded) and distance along the view
    /// axis, from [`project`].
    pub pixel_coords: [f64; 3],
    /// Instance id in the mask (`i + 1`).
    pub index: usize,
    /// Colour name, `null` in variants without colours.
    pub color: Option<String>,
    /// Material name.
    pub material: String,
    /// Visibility in the rendered mask (`visible_pixels`, `bbox`); absent before rendering.
    #[serde(flatten)]
    pub visibility: Option<Visibility>,
}

/// One object's visibility in a rendered mask.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
pub struct Visibility {
    /// Visible pixels.
    pub visible_pixels: u64,
    /// 2D bounding box `[x_min, y_min, x_max, y_max]`, inclusive pixel coordinates, y down;
    /// `null` when the object is not visible at all.
    pub bbox: Option<[u32; 4]>,
}

/// The metadata file of one image.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct ClevrMetadata {
    /// Number of objects.
    pub num_objects: usize,
    /// `test`, `val` or `train`.
    pub split: String,
    /// Image index.
    pub image_index: u64,
    /// `<stem>.png`, `null` unless the RGB pass is produced (reference loaders read every
    /// `*_filename` key).
    pub image_filename: Option<String>,
    /// Backdrop material name.
    pub ground_material: String,
    /// Ground-plane directions.
    pub directions: Directions,
    /// Objects in mask order.
    pub objects: Vec<ObjectMetadata>,
    /// Spatial relationships.
    pub relationships: Relationships,
    /// `<stem>_flat.png`, `null` unless the mask pass is produced.
    pub mask_filename: Option<String>,
    /// `<stem>_normal_0001.png`, `null` unless produced.
    pub normal_filename: Option<String>,
    /// `<stem>_albedo_0001.png`, `null` unless produced.
    pub albedo_filename: Option<String>,
    /// `<stem>_depth_0001.png`, `null` unless produced.
    pub depth_filename: Option<String>,
    /// `<stem>_shadow_0001.png`, `null` unless produced.
    pub shadow_filename: Option<String>,
}

/// Relationships of points `pos` along the four ground directions.
pub fn relationships(pos: &[[f64; 3]], dirs: &Directions) -> Relationships {
    let rel = |d: [f64; 3]| -> Vec<Vec<usize>> {
        pos.iter()
            .enumerate()
            .map(|(i, pi)| {
                (0..pos.len())
                    .filter(|&j| {
                        j != i
                            && dot([pos[j][0] - pi[0], pos[j][1] - pi[1], pos[j][2] - pi[2]], d)
                                > RELATION_EPS
                    })
                    .collect()
            })
            .collect()
    };
    Relationships {
        behind: rel(dirs.behind),
        front: rel(dirs.front),
        left: rel(dirs.left),
        right: rel(dirs.right),
    }
}

/// The CLEVR metadata of a scene, at the scene's render resolution.
pub fn metadata(scene: &SceneFile) -> ClevrMetadata {
    let dirs = directions(&scene.camera);
    let (w, h) = (scene.render.width, scene.render.height);
    let pos: Vec<[f64; 3]> = scene.objects.iter().map(|o| o.location).collect();
    let file = |pass: Pass| {
        scene
            .passes
            .contains(&pass)
            .then(|| names::pass_file(&scene.stem, pass))
    };
    ClevrMetadata {
        num_objects: scene.objects.len(),
        split: scene.split.clone(),
        image_index: scene.index,
        image_filename: file(Pass::Rgb),
        ground_material: scene.backdrop.material.name.clone(),
        directions: dirs,
        objects: scene
            .objects
            .iter()
            .enumerate()
            .map(|(i, o)| ObjectMetadata {
                shape: o.shape.clone(),
                rotation: o.rotation_deg,
                size: o.size.clone(),
                coords_3d: o.location,
                pixel_coords: project(&scene.camera, w, h, o.location),
                index: i + 1,
                color: o.material.color_name.clone(),
                material: o.material.name.clone(),
                visibility: None,
            })
            .collect(),
        relationships: relationships(&pos, &dirs),
        mask_filename: file(Pass::Mask),
        normal_filename: file(Pass::Normal),
        albedo_filename: file(Pass::Albedo),
        depth_filename: file(Pass::Depth),
        shadow_filename: file(Pass::Shadow),
    }
}

/// Camera intrinsics `K` (pixels, origin at the top-left corner, y down, principal point at
/// the centre; Blender's sensor fit `AUTO`).
pub fn intrinsics(scene: &SceneFile) -> [[f64; 3]; 3] {
    let (w, h) = (scene.render.width, scene.render.height);
    let f = crate::camera::focal_px(&scene.camera, w, h);
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

impl CameraMetadata {
    /// The camera of `scene` at its render size.
    pub fn of(scene: &SceneFile) -> CameraMetadata {
        let cam = &scene.camera;
        CameraMetadata {
                intrinsics: intrinsics(scene),
                extrinsics: extrinsics_opencv(scene),
                extrinsics_convention: "world to camera, OpenCV axes (x right, y down, z forward); pixel = K * (E * X) / z, origin at the top-left image corner",
                matrix_world: cam.matrix_world,
                matrix_world_convention: "camera to world, Blender axes (x right, y up, looking along -z)",
                focal_length_mm: cam.focal_length_mm,
                sensor_width_mm: cam.sensor_width_mm,
                sensor_fit: "AUTO",
                clip: [cam.clip_start, cam.clip_end],
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_pass_file_is_under_the_pass_tables_metadata_key() {
        let config = crate::config::Config::builtin("full").unwrap();
        let req = crate::SampleRequest {
            seed: 1,
            index: 0,
            attempt: 0,
            total: 10,
        };
        let mut scene = crate::sample::sample(&config, &req).unwrap();
        scene.passes = Pass::ALL.to_vec();
        let meta = serde_json::to_value(metadata(&scene)).unwrap();
        let keys: Vec<&str> = meta
            .as_object()
            .unwrap()
            .keys()
            .map(String::as_str)
            .filter(|k| k.ends_with("_filename"))
            .collect();
        assert_eq!(keys.len(), Pass::ALL.len(), "{keys:?}");
        for pass in Pass::ALL {
            let key = pass.metadata_key();
            assert_eq!(
                meta[key].as_str(),
                Some(names::pass_file(&scene.stem, pass).as_str()),
                "{key}"
            );
        }
    }

    #[test]
    fn relationships_use_the_threshold() {
        let dirs = Directions {
            behind: [0.0, 1.0, 0.0],
            front: [0.0, -1.0, 0.0],
            left: [-1.0, 0.0, 0.0],
            right: [1.0, 0.0, 0.0],
            above: [0.0, 0.0, 1.0],
            below: [0.0, 0.0, -1.0],
        };
        let pos = [[0.0, 0.0, 0.0], [0.1, 1.0, 0.0], [1.0, 0.15, 0.0]];
        let r = relationships(&pos, &dirs);
        assert_eq!(r.behind, vec![vec![1], vec![], vec![1]]);
        assert_eq!(r.front, vec![vec![], vec![0, 2], vec![]]);
        assert_eq!(r.right, vec![vec![2], vec![2], vec![]]);
        assert_eq!(r.left, vec![vec![], vec![], vec![0, 1]]);
    }
}
