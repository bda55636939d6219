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
//!
//! [`visible_pixel_lower_bounds`] is the other side: per object, the pixels whose every
//! footprint ray certainly meets that object first. Each shape carries balls that its
//! undisplaced mesh encloses ([`inner_balls`]: a ray leaving a ball outwards always meets the
//! mesh, checked in Blender by `blender_scripts/dev/inner_balls.py check` in the test
//! `visibility_bound::`); a pixel counts when its centre ray enters one of the object's balls,
//! shrunk by the footprint, before it can enter any other object's outer body grown by the
//! footprint. A layout where every object's lower bound is over the threshold is one that the
//! visibility render accepts: `generate` skips that render and goes straight to the final
//! render, whose mask is checked as before (again the same accepted layouts).

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

/// The box of the shape's mesh vertices (normalised units: `[lo, hi]` per axis, rounded out by
/// 0.001), and the largest distance of a vertex from the shape's vertical axis. A level-1
/// subdivision moves every vertex to an average of the mesh's vertices, so the rendered
/// surface lies inside both. Measured with `shapes.mesh` in Blender 3.4 (the meshes are built
/// the same vertex for vertex on every version; `visibility_bound::` checks the fit).
pub fn outer_box(shape: &str) -> ([[f64; 2]; 3], f64) {
    match shape {
        "monkey" => ([[-1.0, 1.0], [-0.624, 0.624], [-0.971, 0.471]], 1.066),
        "cone" => ([[-0.967, 0.967], [-0.967, 0.967], [-1.0, 1.0]], 0.967),
        "torus" => ([[-1.0, 1.0], [-1.0, 1.0], [-1.0, -0.499]], 1.0),
        "icosahedron" => ([[-0.895, 0.895], [-0.851, 0.851], [-1.0, 1.0]], 0.895),
        "teapot" => ([[-1.0, 1.0], [-0.624, 0.624], [-1.0, -0.019]], 1.001),
        "sphere" | "cylinder" => ([[-1.0, 1.0]; 3], 1.0),
        _ => ([[-1.0, 1.0]; 3], std::f64::consts::SQRT_2),
    }
}

/// Balls enclosed by the shape's undisplaced mesh (normalised units: `[x, y, z, radius]`),
/// fitted by `blender_scripts/dev/inner_balls.py fit` (greedy cover of the enclosed grid
/// points, each ball shrunk until it is enclosed: exactly inside a closed mesh, sampled
/// densely for the open monkey, whose balls keep a further 10% margin) and rounded down. The
/// teapot has none: rays leak through the seams of its patches and the gap under its lid, so
/// no ball inside it is enclosed and a layout with a teapot is never pre-accepted.
pub fn inner_balls(shape: &str) -> &'static [[f64; 4]] {
    match shape {
        "cube" => &[
            [0.0, 0.0, 0.0, 0.968],
            [-0.4, -0.4, -0.4, 0.576],
            [-0.4, -0.4, 0.4, 0.576],
            [-0.4, 0.4, -0.4, 0.576],
            [-0.4, 0.4, 0.4, 0.576],
            [0.4, -0.4, -0.4, 0.576],
            [0.4, -0.4, 0.4, 0.576],
            [0.4, 0.4, -0.4, 0.576],
            [0.4, 0.4, 0.4, 0.576],
        ],
        "sphere" => &[[0.0, 0.0, 0.0, 0.955]],
        "cylinder" => &[
            [0.0, 0.0, 0.0, 0.961],
            [-0.6, -0.1, -0.6, 0.369],
            [-0.6, -0.1, 0.6, 0.369],
            [-0.1, -0.6, -0.6, 0.369],
            [-0.1, -0.6, 0.6, 0.369],
            [-0.1, 0.6, -0.6, 0.369],
            [-0.1, 0.6, 0.6, 0.369],
            [0.6, -0.1, -0.6, 0.369],
            [0.6, -0.1, 0.6, 0.369],
            [0.4, 0.4, -0.6, 0.383],
            [0.4, 0.4, 0.6, 0.383],
            [-0.5, 0.3, -0.6, 0.383],
        ],
        "monkey" => &[
            [0.0, 0.1, 0.0, 0.374],
            [0.0, -0.1, -0.1, 0.304],
            [-0.2, 0.1, 0.0, 0.327],
            [0.2, 0.1, 0.0, 0.31],
            [0.0, -0.4, -0.6, 0.126],
            [-0.2, -0.2, -0.1, 0.227],
            [0.2, -0.2, -0.1, 0.167],
            [0.0, -0.2, -0.3, 0.218],
            [0.0, 0.1, -0.1, 0.356],
            [-0.4, -0.2, -0.1, 0.128],
            [0.0, -0.4, -0.3, 0.128],
            [0.4, -0.2, -0.1, 0.104],
        ],
        "cone" => &[
            [0.0, 0.0, -0.4, 0.581],
            [-0.3, -0.2, -0.6, 0.372],
            [-0.2, 0.3, -0.6, 0.372],
            [0.2, -0.3, -0.6, 0.372],
            [0.3, 0.2, -0.6, 0.372],
            [0.0, 0.0, 0.1, 0.33],
            [-0.5, 0.1, -0.7, 0.286],
            [-0.1, -0.5, -0.7, 0.286],
            [0.1, 0.5, -0.7, 0.286],
            [0.5, -0.1, -0.7, 0.286],
            [-0.6, -0.3, -0.8, 0.189],
            [-0.3, 0.6, -0.8, 0.189],
        ],
        "torus" => &[
            [-0.7, -0.3, -0.8, 0.184],
            [-0.7, 0.2, -0.8, 0.183],
            [-0.6, 0.5, -0.8, 0.176],
            [-0.5, -0.6, -0.8, 0.176],
            [-0.3, 0.7, -0.8, 0.184],
            [-0.2, -0.7, -0.8, 0.183],
            [0.2, -0.7, -0.8, 0.183],
            [0.2, 0.7, -0.8, 0.183],
            [0.5, -0.6, -0.8, 0.176],
            [0.5, 0.5, -0.8, 0.172],
            [0.7, -0.3, -0.8, 0.184],
            [0.7, 0.2, -0.8, 0.183],
        ],
        "icosahedron" => &[[0.0, 0.0, 0.0, 0.77]],
        _ => &[],
    }
}

/// How far (pixels, along each axis) a pixel's first sample may lie from its centre, with
/// Blender's pixel filter of `filter_width` pixels.
pub fn sample_reach(filter_width: f64) -> f64 {
    0.5 + filter_width.max(0.0) / 2.0
}

/// One object in camera coordinates (x right, y up, looking along -z; a ray's parameter is
/// the depth along the view axis), its outer bodies grown by the footprint.
struct Body {
    /// Centre of the box.
    centre: [f64; 3],
    /// The box's local x, y, z axes.
    axes: [[f64; 3]; 3],
    /// Half sides of the box, grown.
    half: [f64; 3],
    /// The object's origin (the ball's centre, on the vertical axis).
    origin: [f64; 3],
    /// Radius of the outer ball, grown.
    outer: f64,
    /// Radius of the vertical cylinder around the origin, grown.
    radial: f64,
}

fn to_camera(scene: &SceneFile, p: [f64; 3]) -> [f64; 3] {
    let m = &scene.camera.matrix_world;
    let d = [p[0] - m[0][3], p[1] - m[1][3], p[2] - m[2][3]];
    [dot(d, axis(m, 0)), dot(d, axis(m, 1)), dot(d, axis(m, 2))]
}

/// A point of the object's normalised frame in world coordinates.
fn to_world(o: &SceneObject, p: [f64; 3]) -> [f64; 3] {
    let s = o.scale;
    let (sin, cos) = o.rotation_deg.to_radians().sin_cos();
    [
        o.location[0] + s * (cos * p[0] - sin * p[1]),
        o.location[1] + s * (sin * p[0] + cos * p[1]),
        o.location[2] + s * p[2],
    ]
}

fn body(scene: &SceneFile, o: &SceneObject, slope: f64) -> Body {
    let m = &scene.camera.matrix_world;
    let s = o.scale;
    let origin = to_camera(scene, o.location);
    let (sin, cos) = o.rotation_deg.to_radians().sin_cos();
    let world_axes = [[cos, sin, 0.0], [-sin, cos, 0.0], [0.0, 0.0, 1.0]];
    let axes = world_axes.map(|a| [dot(a, axis(m, 0)), dot(a, axis(m, 1)), dot(a, axis(m, 2))]);
    let radius = s * outer_radius(&o.shape);
    let depth = -origin[2];
    // Every ray of a pixel's footprint, at depth t, is within `t * slope` of the centre ray;
    // the object's points have depth at most `depth + radius`.
    let grow = ((depth + radius) * slope).max(0.0);
    let (bounds, radial) = outer_box(&o.shape);
    let mid = bounds.map(|[lo, hi]| (lo + hi) / 2.0);
    Body {
        centre: to_camera(scene, to_world(o, mid)),
        axes,
        half: bounds.map(|[lo, hi]| s * (hi - lo) / 2.0 + grow),
        origin,
        outer: radius + grow,
        radial: s * radial + grow,
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
    for (a, &half) in b.axes.iter().zip(&b.half) {
        let p = dot(*a, b.centre);
        let q = dot(*a, d);
        if q.abs() < 1e-12 {
            if p.abs() > half {
                return None;
            }
            continue;
        }
        let (t0, t1) = ((p - half) / q, (p + half) / q);
        lo = lo.max(t0.min(t1));
        hi = hi.min(t0.max(t1));
    }
    (lo <= hi).then_some((lo, hi))
}

/// Depths where the ray `t * d` is inside the infinite cylinder of radius `r` around the line
/// through `c` along the unit vector `a`: `None` when it misses.
fn cylinder_hit(d: [f64; 3], c: [f64; 3], a: [f64; 3], r: f64) -> Option<(f64, f64)> {
    let (da, ca) = (dot(d, a), dot(c, a));
    let dp = [d[0] - da * a[0], d[1] - da * a[1], d[2] - da * a[2]];
    let cp = [c[0] - ca * a[0], c[1] - ca * a[1], c[2] - ca * a[2]];
    let qa = dot(dp, dp);
    let qc = dot(cp, cp) - r * r;
    if qa < 1e-18 {
        return (qc <= 0.0).then_some((f64::NEG_INFINITY, f64::INFINITY));
    }
    let qb = dot(dp, cp);
    let disc = qb * qb - qa * qc;
    if disc < 0.0 {
        return None;
    }
    let q = disc.sqrt();
    Some(((qb - q) / qa, (qb + q) / qa))
}

/// Where the ray `t * d` may first meet the object: the first depth inside its grown box,
/// ball and vertical cylinder, or `None` when no ray of the footprint can hit it in front of
/// the camera.
fn outer_entry(d: [f64; 3], b: &Body) -> Option<f64> {
    let (b0, b1) = box_hit(d, b)?;
    let (s0, s1) = ball_hit(d, b.origin, b.outer)?;
    let (c0, c1) = cylinder_hit(d, b.origin, b.axes[2], b.radial)?;
    let (lo, hi) = (b0.max(s0).max(c0), b1.min(s1).min(c1));
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
                p[c] += sign * b.half[i] * a[c];
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

/// A scene as both bounds see it: the image, the focal length in pixels, and each object's
/// outer body and shrunk enclosed balls in camera coordinates.
struct View {
    w: u32,
    h: u32,
    f: f64,
    bodies: Vec<Body>,
    balls: Vec<Vec<([f64; 3], f64)>>,
}

impl View {
    /// `None` where no sound bound is known: an image under Blender's smallest size of 4x4
    /// pixels (Blender renders more pixels than asked).
    fn of(scene: &SceneFile) -> Option<View> {
        let (w, h) = (scene.render.width, scene.render.height);
        if w < 4 || h < 4 {
            return None;
        }
        let f = focal_px(&scene.camera, w, h);
        // A sample `reach` pixels off the centre along x and y turns the ray's direction by at
        // most `reach * sqrt 2 / f` per unit depth.
        let slope =
            sample_reach(f64::from(scene.render.filter_width)) * std::f64::consts::SQRT_2 / f;
        let objects = &scene.objects;
        Some(View {
            w,
            h,
            f,
            bodies: objects.iter().map(|o| body(scene, o, slope)).collect(),
            balls: objects
                .iter()
                .map(|o| shrunk_balls(scene, o, slope))
                .collect(),
        })
    }

    /// The pixels of object `i`'s rectangle whose centre ray `d` passes `keep(d)`.
    fn count(&self, i: usize, keep: impl Fn([f64; 3]) -> bool) -> u64 {
        let (w, h, f) = (self.w, self.h, self.f);
        let (x0, x1, y0, y1) = pixel_rect(&self.bodies[i], f, w, h);
        let mut count = 0u64;
        for y in y0..y1 {
            for x in x0..x1 {
                let d = [
                    (f64::from(x) + 0.5 - f64::from(w) / 2.0) / f,
                    -(f64::from(y) + 0.5 - f64::from(h) / 2.0) / f,
                    -1.0,
                ];
                if keep(d) {
                    count += 1;
                }
            }
        }
        count
    }

    /// The bodies or balls of every object but `i`.
    fn others<'a, T>(&self, all: &'a [T], i: usize) -> impl Iterator<Item = &'a T> {
        all.iter()
            .enumerate()
            .filter(move |&(j, _)| j != i)
            .map(|(_, t)| t)
    }
}

/// For each object of `scene`, in order, an upper bound on the pixels it gets in the
/// object-index pass of the undisplaced visibility render at the scene's size (see the module
/// documentation). `None` where no sound bound is known ([`View::of`]).
pub fn visible_pixel_bounds(scene: &SceneFile) -> Option<Vec<u64>> {
    let v = View::of(scene)?;
    let bounds = (0..scene.objects.len())
        .map(|i| {
            let covers: Vec<([f64; 3], f64)> = v.others(&v.balls, i).flatten().copied().collect();
            v.count(i, |d| {
                let Some(entry) = outer_entry(d, &v.bodies[i]) else {
                    return false;
                };
                !covers
                    .iter()
                    .any(|&(c, r)| ball_hit(d, c, r).is_some_and(|(t0, _)| t0 > 0.0 && t0 < entry))
            })
        })
        .collect();
    Some(bounds)
}

/// An object's balls in camera coordinates, each shrunk by the footprint's reach at its depth
/// (a ball that shrinks away is dropped).
fn shrunk_balls(scene: &SceneFile, o: &SceneObject, slope: f64) -> Vec<([f64; 3], f64)> {
    inner_balls(&o.shape)
        .iter()
        .filter_map(|&[x, y, z, r]| {
            let c = to_camera(scene, to_world(o, [x, y, z]));
            let r = r * o.scale;
            let r = r - ((-c[2] + r) * slope).max(0.0);
            (r > 0.0 && -c[2] - r > 1e-6).then_some((c, r))
        })
        .collect()
}

/// For each object of `scene`, in order, a lower bound on the pixels it gets in the
/// object-index pass of the undisplaced visibility render at the scene's size (see the module
/// documentation); `None` where [`visible_pixel_bounds`] has none.
pub fn visible_pixel_lower_bounds(scene: &SceneFile) -> Option<Vec<u64>> {
    let v = View::of(scene)?;
    let bounds = (0..scene.objects.len())
        .map(|i| {
            if v.balls[i].is_empty() {
                return 0;
            }
            v.count(i, |d| {
                // The depth by which every footprint ray has met the object.
                let Some(met) = v.balls[i]
                    .iter()
                    .filter_map(|&(c, r)| ball_hit(d, c, r).map(|(t0, _)| t0))
                    .filter(|&t0| t0 > 0.0)
                    .min_by(f64::total_cmp)
                else {
                    return false;
                };
                v.others(&v.bodies, i)
                    .all(|b| outer_entry(d, b).is_none_or(|e| e > met))
            })
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

    /// A scene's first object as a ball at the origin: about `pi (f r / D)^2` pixels.
    fn disc_px(s: &SceneFile) -> f64 {
        let d = crate::camera::dot(s.camera.location, s.camera.location).sqrt();
        let f = focal_px(&s.camera, s.render.width, s.render.height);
        std::f64::consts::PI * (f * s.objects[0].scale / d).powi(2)
    }

    /// A small sphere right behind a big cube on the camera's line of sight, and the
    /// horizontal direction from the camera to the cube.
    fn sphere_behind_cube() -> (SceneFile, [f64; 3]) {
        let mut s = scene(1);
        s.objects.truncate(2);
        let cam = s.camera.location;
        let dir = crate::camera::normalize([-cam[0], -cam[1], 0.0]);
        s.objects[0].shape = "cube".into();
        s.objects[0].scale = 0.9;
        s.objects[0].location = [0.0, 0.0, 0.9];
        s.objects[1].shape = "sphere".into();
        s.objects[1].scale = 0.2;
        s.objects[1].location = [dir[0] * 2.0, dir[1] * 2.0, 0.2];
        (s, dir)
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
        let disc = disc_px(&s);
        assert!(b as f64 > disc, "{b} vs {disc}");
        assert!((b as f64) < 6.0 * disc, "{b} vs {disc}");
    }

    #[test]
    fn an_object_behind_a_big_cube_is_bounded_to_nothing_and_off_screen_is_zero() {
        let (mut s, dir) = sphere_behind_cube();
        let b = visible_pixel_bounds(&s).unwrap();
        assert!(b[0] > 1000, "{b:?}");
        assert_eq!(b[1], 0, "{b:?}");
        // Far off to the side: nothing in the image.
        s.objects[1].location = [dir[1] * 40.0, -dir[0] * 40.0, 0.2];
        assert_eq!(visible_pixel_bounds(&s).unwrap()[1], 0);
    }

    #[test]
    fn the_lower_bound_is_under_the_upper_and_a_lone_sphere_near_its_disc() {
        for index in 0..40 {
            let s = scene(index);
            let lower = visible_pixel_lower_bounds(&s).unwrap();
            let upper = visible_pixel_bounds(&s).unwrap();
            for (l, u) in lower.iter().zip(&upper) {
                assert!(l <= u, "layout {index}: {lower:?} vs {upper:?}");
            }
        }
        let mut s = scene(0);
        s.objects.truncate(1);
        let o = &mut s.objects[0];
        o.shape = "sphere".into();
        o.location = [0.0, 0.0, o.scale];
        let l = visible_pixel_lower_bounds(&s).unwrap()[0] as f64;
        let disc = disc_px(&s);
        // The ball of radius 0.955, less the footprint: most of the disc, never more.
        assert!(l < disc && l > 0.6 * disc, "{l} vs {disc}");
        // A teapot has no enclosed ball: never pre-accepted.
        s.objects[0].shape = "teapot".into();
        assert_eq!(visible_pixel_lower_bounds(&s).unwrap()[0], 0);
    }

    #[test]
    fn an_object_behind_another_has_no_certain_pixel_where_they_overlap() {
        let (mut s, _) = sphere_behind_cube();
        let cam = s.camera.location;
        let l = visible_pixel_lower_bounds(&s).unwrap();
        assert_eq!(l[1], 0, "{l:?}");
        assert!(l[0] > 1000, "{l:?}");
        // In front of the cube, the sphere's lower bound is its own alone, and the cube loses
        // the pixels the sphere may cover.
        let c = [0.0, 0.0, 0.9];
        s.objects[1].location = [0, 1, 2].map(|k| c[k] + 0.3 * (cam[k] - c[k]));
        let l = visible_pixel_lower_bounds(&s).unwrap();
        let mut alone = s.clone();
        alone.objects.remove(0);
        assert_eq!(
            l[1],
            visible_pixel_lower_bounds(&alone).unwrap()[0],
            "{l:?}"
        );
        assert!(l[1] > 20, "{l:?}");
        let mut cube = s.clone();
        cube.objects.truncate(1);
        assert!(
            l[0] < visible_pixel_lower_bounds(&cube).unwrap()[0],
            "{l:?}"
        );
    }

    #[test]
    fn images_under_four_pixels_have_no_bound() {
        let mut s = scene(2);
        s.render.width = 3;
        assert!(visible_pixel_bounds(&s).is_none());
        assert!(visible_pixel_lower_bounds(&s).is_none());
    }
}
