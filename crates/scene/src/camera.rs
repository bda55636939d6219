//! Poses and the pinhole camera model, matching Blender's.

use serde::Serialize;

use crate::scene_file::Camera;

/// A row-major 4x4 matrix (`m[row][col]`), as stored in scene files.
pub type Matrix4 = [[f64; 4]; 4];

fn sub(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}

pub(crate) fn dot(a: [f64; 3], b: [f64; 3]) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

fn cross(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}

pub(crate) fn normalize(a: [f64; 3]) -> [f64; 3] {
    let n = dot(a, a).sqrt();
    if n == 0.0 {
        return a;
    }
    [a[0] / n, a[1] / n, a[2] / n]
}

/// Column `c` of the rotation part of `m` (the local axis `c` in world space).
pub(crate) fn axis(m: &Matrix4, c: usize) -> [f64; 3] {
    [m[0][c], m[1][c], m[2][c]]
}

/// The world matrix of an object at `location` whose local -Z points along `forward` and whose
/// local +Y leans towards world +Z, as Blender's track-to constraint (`TRACK_NEGATIVE_Z`,
/// `UP_Y`) makes it. When `forward` is vertical, world +Y plays the part of "up".
pub fn track_matrix(location: [f64; 3], forward: [f64; 3]) -> Matrix4 {
    let z = normalize([-forward[0], -forward[1], -forward[2]]);
    let mut up = [0.0, 0.0, 1.0];
    if dot(up, z).abs() > 1.0 - 1e-9 {
        up = [0.0, 1.0, 0.0];
    }
    let d = dot(up, z);
    let y = normalize([up[0] - d * z[0], up[1] - d * z[1], up[2] - d * z[2]]);
    let x = cross(y, z);
    [
        [x[0], y[0], z[0], location[0]],
        [x[1], y[1], z[1], location[1]],
        [x[2], y[2], z[2], location[2]],
        [0.0, 0.0, 0.0, 1.0],
    ]
}

/// The world matrix of an object at `location` tracking `target` (track-to constraint).
pub fn look_at_matrix(location: [f64; 3], target: [f64; 3]) -> Matrix4 {
    track_matrix(location, sub(target, location))
}

/// Focal length in pixels for Blender's sensor fit `AUTO`: the sensor width spans the larger
/// image dimension (horizontal when `width >= height`, vertical otherwise); square pixels.
pub fn focal_px(camera: &Camera, width: u32, height: u32) -> f64 {
    camera.focal_length_mm / camera.sensor_width_mm * f64::from(width.max(height))
}

/// Project a world point to `[x, y, depth]`: pixel coordinates with the origin at the image's
/// top-left corner, x right, y down (pixel `(i, j)` covers `[i, i+1) x [j, j+1)`), principal
/// point at the centre, and depth the distance along the camera's view axis (Blender's
/// `world_to_camera_view` z). Points behind the camera get a negative depth.
pub fn project(camera: &Camera, width: u32, height: u32, p: [f64; 3]) -> [f64; 3] {
    let m = &camera.matrix_world;
    let d = sub(p, [m[0][3], m[1][3], m[2][3]]);
    let xc = dot(d, axis(m, 0));
    let yc = dot(d, axis(m, 1));
    let depth = -dot(d, axis(m, 2));
    let f = focal_px(camera, width, height);
    [
        f64::from(width) / 2.0 + f * xc / depth,
        f64::from(height) / 2.0 - f * yc / depth,
        depth,
    ]
}

/// Unit vector of the camera's local axis `c` (0 = right, 1 = up) with the sign `s`, projected
/// on the ground plane.
fn ground_axis(camera: &Camera, c: usize, s: f64) -> [f64; 3] {
    let a = axis(&camera.matrix_world, c);
    normalize([s * a[0], s * a[1], 0.0])
}

/// The six ground-plane directions (unit vectors) from the camera.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Directions {
    /// Away from the camera.
    pub behind: [f64; 3],
    /// Towards the camera.
    pub front: [f64; 3],
    /// The camera's left.
    pub left: [f64; 3],
    /// The camera's right.
    pub right: [f64; 3],
    /// World up.
    pub above: [f64; 3],
    /// World down.
    pub below: [f64; 3],
}

/// The six CLEVR directions from the camera: `behind` is the view direction projected on the
/// ground, `left` the camera's -X projected on the ground, `above` world +Z; the others are
/// their opposites.
pub fn directions(camera: &Camera) -> Directions {
    let behind = ground_axis(camera, 2, -1.0);
    let left = ground_axis(camera, 0, -1.0);
    let neg = |a: [f64; 3]| [-a[0], -a[1], -a[2]];
    Directions {
        behind,
        front: neg(behind),
        left,
        right: neg(left),
        above: [0.0, 0.0, 1.0],
        below: [0.0, 0.0, -1.0],
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn camera(location: [f64; 3]) -> Camera {
        Camera {
            location,
            look_at: [0.0; 3],
            matrix_world: look_at_matrix(location, [0.0; 3]),
            focal_length_mm: 35.0,
            sensor_width_mm: 32.0,
            clip_start: 0.1,
            clip_end: 100.0,
        }
    }

    #[test]
    fn track_matrix_is_orthonormal_and_points_minus_z_at_target() {
        let m = look_at_matrix([7.481, -6.508, 5.344], [0.0; 3]);
        for i in 0..3 {
            for j in 0..3 {
                let d = dot(axis(&m, i), axis(&m, j));
                let want = if i == j { 1.0 } else { 0.0 };
                assert!((d - want).abs() < 1e-12, "axes {i},{j}: {d}");
            }
        }
        let fwd = normalize([-7.481, 6.508, -5.344]);
        let minus_z = axis(&m, 2).map(|v| -v);
        assert!((dot(fwd, minus_z) - 1.0).abs() < 1e-12);
        // Local +Y leans up, local +X is horizontal (no roll).
        assert!(axis(&m, 1)[2] > 0.0);
        assert!(axis(&m, 0)[2].abs() < 1e-12);
        // Right-handed.
        let c = cross(axis(&m, 0), axis(&m, 1));
        assert!((dot(c, axis(&m, 2)) - 1.0).abs() < 1e-12);
    }

    #[test]
    fn target_projects_to_the_centre_and_right_is_right() {
        let cam = camera([7.481, -6.508, 5.344]);
        let p = project(&cam, 320, 240, [0.0; 3]);
        assert!((p[0] - 160.0).abs() < 1e-9 && (p[1] - 120.0).abs() < 1e-9);
        let dist = dot(cam.location, cam.location).sqrt();
        assert!((p[2] - dist).abs() < 1e-9);
        // A point up in the world appears above the centre (smaller y).
        assert!(project(&cam, 320, 240, [0.0, 0.0, 1.0])[1] < 120.0);
        // A point along the camera's right axis appears right of the centre.
        let r = axis(&cam.matrix_world, 0);
        assert!(project(&cam, 320, 240, r)[0] > 160.0);
    }

    #[test]
    fn sensor_fit_auto_uses_the_larger_dimension() {
        let cam = camera([0.0, -10.0, 0.0]);
        // One metre right of the target at distance 10: f_px * 0.1.
        let wide = project(&cam, 320, 240, [1.0, 0.0, 0.0]);
        assert!((wide[0] - (160.0 + 35.0 / 32.0 * 320.0 * 0.1)).abs() < 1e-9);
        let tall = project(&cam, 240, 320, [1.0, 0.0, 0.0]);
        assert!((tall[0] - (120.0 + 35.0 / 32.0 * 320.0 * 0.1)).abs() < 1e-9);
    }

    #[test]
    fn directions_follow_the_camera() {
        let cam = camera([0.0, -10.0, 5.0]);
        let d = directions(&cam);
        assert!((d.behind[1] - 1.0).abs() < 1e-12);
        assert!((d.left[0] + 1.0).abs() < 1e-12);
        assert_eq!(d.above, [0.0, 0.0, 1.0]);
    }
}
