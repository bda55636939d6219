//! An upper bound on each object's visible pixels, from the scene's geometry and camera alone.
//!
//! `generate` rejects a layout when an object has at most the threshold of pixels in the
//! 1-spp visibility render ([`threshold`]). That render is
//! undisplaced: every object is its shape's mesh under a level-1 subdivision, which lies
//! inside the convex hull of the mesh's vertices, so inside the box `[-1, 1]^3` of the
//! normalised shape (`blender_scripts/shapes.py`) and inside a ball of the shape's radius.
//! A pixel belongs to an object in the object-index pass when the ray of its first sample hits
//! that object first; the sample lies within `0.5 + filter_width / 2` pixels of the pixel's
//! centre along each axis. [`visible_pixel_bounds`] counts, per object, the pixels of the image
//! where some ray of that footprint could hit the object (its outer body grown by the
//! footprint) and that are not certainly covered first by another object (an inner ball of a
//! closed shape, shrunk by the footprint, entered before the object's outer body). The count is
//! never below what Blender counts, so a layout where a bound is at or under the threshold is
//! one that the visibility render rejects: `generate` skips that render and resamples (the
//! same attempts, the same accepted layouts, fewer Blender renders).

use crate::camera::{axis, dot, focal_px};
use crate::scene_file::{SceneFile, SceneObject};

/// The visibility threshold at a resolution: an object needs MORE than this many pixels.
/// 200 px at 320x240 (the reference), scaled by the pixel count.
pub fn threshold(width: u32, height: u32) -> u64 {
    (200.0 * (f64::from(width) * f64::from(height)) / (320.0 * 240.0)).round() as u64
}

/// Radius (normalised units) of a ball around the shape's centre holding its mesh: the vertex
/// hull of the sphere (radius 1), torus (major 0.75 + minor 0.25, height 0.25), cylinder and
/// cone (radius 1, height 2), and every other shape's box `[-1, 1]^3`.
fn outer_radius(shape: &str) -> f64 {
    match shape {
        "sphere" => 1.0,
        "torus" => (1.0f64 + 0.25 * 0.25).sqrt(),
        "cylinder" | "cone" => std::f64::consts::SQRT_2,
        _ => 3f64.sqrt(),
    }
}

/// A ball inside the shape's closed mesh (normalised units): `(centre z, radius)`, or `None`
/// for shapes whose mesh is open or holed (monkey, teapot, torus), which never count as
/// covering another object. The radii are about 10% under the shape's inscribed ball (cube and
/// cylinder 1, sphere 1, cone 0.618 at z = -0.382, icosahedron 0.795), for the subdivision's
/// shrinking and the bevels.
fn inner_ball(shape: &str) -> Option<(f64, f64)> {
    match shape {
        "cube" | "sphere" | "cylinder" => Some((0.0, 0.9)),
        "cone" => Some((-0.382, 0.45)),
        "icosahedron" => Some((0.0, 0.7)),
        _ => None,
    }
}

/// How far (pixels, along each axis) a pixel's first sample may lie from its centre, with
/// Blender's pixel filter of `filter_width` pixels.
pub fn sample_reach(filter_width: f64) -> f64 {
    0.5 + filter_width.max(0.0) / 2.0
}

/// One object in camera coordinates (x right, y up, looking along -z; a ray's parameter is
/// the depth along the view axis).
struct Body {
    /// Centre of the box.
    centre: [f64; 3],
    /// The box's local x, y, z axes.
    axes: [[f64; 3]; 3],
    /// Half side of the box, grown by `grow`.
    half: f64,
    /// Radius of the outer ball, grown by `grow`.
    outer: f64,
    /// Inner ball: centre and radius, shrunk by `grow` (absent when the shape has none or it
    /// shrank away).
    inner: Option<([f64; 3], f64)>,
}

fn to_camera(scene: &SceneFile, p: [f64; 3]) -> [f64; 3] {
    let m = &scene.camera.matrix_world;
    let d = [p[0] - m[0][3], p[1] - m[1][3], p[2] - m[2][3]];
    [dot(d, axis(m, 0)), dot(d, axis(m, 1)), dot(d, axis(m, 2))]
}

fn body(scene: &SceneFile, o: &SceneObject, slope: f64) -> Body {
    let m = &scene.camera.matrix_world;
    let s = o.scale;
    let world_centre = o.location;
    let centre = to_camera(scene, world_centre);
    let (sin, cos) = o.rotation_deg.to_radians().sin_cos();
    let world_axes = [[cos, sin, 0.0], [-sin, cos, 0.0], [0.0, 0.0, 1.0]];
    let axes = world_axes.map(|a| [dot(a, axis(m, 0)), dot(a, axis(m, 1)), dot(a, axis(m, 2))]);
    let radius = s * outer_radius(&o.shape);
    let depth = -centre[2];
    // Every ray of a pixel's footprint, at depth t, is within `t * slope` of the centre ray;
    // the object's points have depth at most `depth + radius`.
    let grow = ((depth + radius) * slope).max(0.0);
    let inner = inner_ball(&o.shape).and_then(|(z, r)| {
        let c = to_camera(
            scene,
            [world_centre[0], world_centre[1], world_centre[2] + z * s],
        );
        let r = r * s - grow;
        (r > 0.0).then_some((c, r))
    });
    Body {
        centre,
        axes,
        half: s + grow,
        outer: radius + grow,
        inner,
    }
}

/// Depths where the ray `t * d` is inside the ball: `None` when it misses.
fn ball_hit(d: [f64; 3], c: [f64; 3], r: f64) -> Option<(f64, f64)> {
    let a = dot(d, d);
    let b = dot(d, c);
    let disc = b * b - a * (dot(c, c) - r * r);
    if disc < 0.0 {
        return None;
    }
    let q = disc.sqrt();
    Some(((b - q) / a, (b + q) / a))
}

/// Depths where the ray `t * d` is inside the box (slab test): `None` when it misses.
fn box_hit(d: [f64; 3], b: &Body) -> Option<(f64, f64)> {
    let (mut lo, mut hi) = (f64::NEG_INFINITY, f64::INFINITY);
    for a in &b.axes {
        let p = dot(*a, b.centre);
        let q = dot(*a, d);
        if q.abs() < 1e-12 {
            if p.abs() > b.half {
                return None;
            }
            continue;
        }
        let (t0, t1) = ((p - b.half) / q, (p + b.half) / q);
        lo = lo.max(t0.min(t1));
        hi = hi.min(t0.max(t1));
    }
    (lo <= hi).then_some((lo, hi))
}

/// Where the ray `t * d` may first meet the object: the first depth inside both its grown box
/// and grown ball, or `None` when no ray of the footprint can hit it in front of the camera.
fn outer_entry(d: [f64; 3], b: &Body) -> Option<f64> {
    let (b0, b1) = box_hit(d, b)?;
    let (s0, s1) = ball_hit(d, b.centre, b.outer)?;
    let (lo, hi) = (b0.max(s0), b1.min(s1));
    (lo <= hi && hi > 0.0).then_some(lo)
}

/// Pixels of the image whose rays may meet `b`: its bounding rectangle (the projected corners
/// of its grown box), or the whole image when part of it is behind the camera.
fn pixel_rect(b: &Body, f: f64, w: u32, h: u32) -> (u32, u32, u32, u32) {
    let (mut x0, mut x1, mut y0, mut y1) = (
        f64::INFINITY,
        f64::NEG_INFINITY,
        f64::INFINITY,
        f64::NEG_INFINITY,
    );
    for k in 0..8 {
        let mut p = b.centre;
        for (i, a) in b.axes.iter().enumerate() {
            let sign = if k >> i & 1 == 1 { 1.0 } else { -1.0 };
            for c in 0..3 {
                p[c] += sign * b.half * a[c];
            }
        }
        let depth = -p[2];
        if depth <= 1e-9 {
            return (0, w, 0, h);
        }
        let (x, y) = (
            f64::from(w) / 2.0 + f * p[0] / depth,
            f64::from(h) / 2.0 - f * p[1] / depth,
        );
        x0 = x0.min(x);
        x1 = x1.max(x);
        y0 = y0.min(y);
        y1 = y1.max(y);
    }
    let clamp = |v: f64, n: u32| v.clamp(0.0, f64::from(n)) as u32;
    (
        clamp(x0.floor() - 1.0, w),
        clamp(x1.ceil() + 1.0, w),
        clamp(y0.floor() - 1.0, h),
        clamp(y1.ceil() + 1.0, h),
    )
}

/// For each object of `scene`, in order, an upper bound on the pixels it gets in the
/// object-index pass of the undisplaced visibility render at the scene's size (see the module
/// documentation). `None` where no sound bound is known: an image under Blender's smallest
/// size of 4x4 pixels (Blender renders more pixels than asked).
pub fn visible_pixel_bounds(scene: &SceneFile) -> Option<Vec<u64>> {
    let (w, h) = (scene.render.width, scene.render.height);
    if w < 4 || h < 4 {
        return None;
    }
    let f = focal_px(&scene.camera, w, h);
    // A sample `reach` pixels off the centre along x and y turns the ray's direction by at
    // most `reach * sqrt 2 / f` per unit depth.
    let slope = sample_reach(f64::from(scene.render.filter_width)) * std::f64::consts::SQRT_2 / f;
    let bodies: Vec<Body> = scene
        .objects
        .iter()
        .map(|o| body(scene, o, slope))
        .collect();
    let bounds = bodies
        .iter()
        .enumerate()
        .map(|(i, b)| {
            let covers: Vec<([f64; 3], f64)> = bodies
                .iter()
                .enumerate()
                .filter(|&(j, _)| j != i)
                .filter_map(|(_, o)| o.inner)
                .collect();
            let (x0, x1, y0, y1) = pixel_rect(b, f, w, h);
            let mut count = 0u64;
            for y in y0..y1 {
                for x in x0..x1 {
                    let d = [
                        (f64::from(x) + 0.5 - f64::from(w) / 2.0) / f,
                        -(f64::from(y) + 0.5 - f64::from(h) / 2.0) / f,
                        -1.0,
                    ];
                    let Some(entry) = outer_entry(d, b) else {
                        continue;
                    };
                    let hidden = covers.iter().any(|&(c, r)| {
                        ball_hit(d, c, r).is_some_and(|(t0, _)| t0 > 0.0 && t0 < entry)
                    });
                    if !hidden {
                        count += 1;
                    }
                }
            }
            count
        })
        .collect();
    Some(bounds)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::config::Config;
    use crate::sample::{sample, SampleRequest};

    fn scene(index: u64) -> SceneFile {
        let c = Config::builtin("full").unwrap();
        sample(
            &c,
            &SampleRequest {
                seed: 3,
                index,
                attempt: 0,
                total: 100,
            },
        )
        .unwrap()
    }

    #[test]
    fn a_lone_object_in_view_is_bounded_by_its_projected_size() {
        let mut s = scene(0);
        s.objects.truncate(1);
        let o = &mut s.objects[0];
        o.location = [0.0, 0.0, o.scale];
        let b = visible_pixel_bounds(&s).unwrap()[0];
        // A sphere of radius r at distance D covers about pi (f r / D)^2 pixels; the bound is
        // at least that and not wildly more (the box, the footprint).
        let d = crate::camera::dot(s.camera.location, s.camera.location).sqrt();
        let f = focal_px(&s.camera, s.render.width, s.render.height);
        let disc = std::f64::consts::PI * (f * s.objects[0].scale / d).powi(2);
        assert!(b as f64 > disc, "{b} vs {disc}");
        assert!((b as f64) < 6.0 * disc, "{b} vs {disc}");
    }

    #[test]
    fn an_object_behind_a_big_cube_is_bounded_to_nothing_and_off_screen_is_zero() {
        let mut s = scene(1);
        s.objects.truncate(2);
        // Put a small sphere right behind a big cube on the camera's line of sight.
        let cam = s.camera.location;
        let dir = crate::camera::normalize([-cam[0], -cam[1], 0.0]);
        s.objects[0].shape = "cube".into();
        s.objects[0].scale = 0.9;
        s.objects[0].location = [0.0, 0.0, 0.9];
        s.objects[1].shape = "sphere".into();
        s.objects[1].scale = 0.2;
        s.objects[1].location = [dir[0] * 2.0, dir[1] * 2.0, 0.2];
        let b = visible_pixel_bounds(&s).unwrap();
        assert!(b[0] > 1000, "{b:?}");
        assert_eq!(b[1], 0, "{b:?}");
        // Far off to the side: nothing in the image.
        s.objects[1].location = [dir[1] * 40.0, -dir[0] * 40.0, 0.2];
        assert_eq!(visible_pixel_bounds(&s).unwrap()[1], 0);
    }

    #[test]
    fn images_under_four_pixels_have_no_bound() {
        let mut s = scene(2);
        s.render.width = 3;
        assert!(visible_pixel_bounds(&s).is_none());
    }
}
