//! How many pixels an object would cover with nothing in front of it: the convex hull of its
//! projected outline, clipped to the image. Exact for the convex shapes whose outline is the
//! hull of a few points (cube: its 8 corners; cylinder: its two rims; sphere: points on its
//! surface, within about 0.1%); other shapes give `None` (a hull would overstate them).
//! The share occluded is then `1 - visible_pixels / area`.

/// A sample's camera: intrinsics `K` and world-to-camera `E` (OpenCV axes), and its position
/// (read from our metadata by `data.rs`).
#[derive(Debug, Clone)]
pub struct Camera {
    pub k: [[f64; 3]; 3],
    pub e: [[f64; 4]; 4],
    pub location: [f64; 3],
}

impl Camera {
    /// Pixel coordinates of world point `p` (x right, y down), `None` behind the camera.
    pub fn project(&self, p: [f64; 3]) -> Option<[f64; 2]> {
        let c: Vec<f64> = (0..3)
            .map(|r| self.e[r][0] * p[0] + self.e[r][1] * p[1] + self.e[r][2] * p[2] + self.e[r][3])
            .collect();
        if c[2] <= 1e-6 {
            return None;
        }
        let u = self.k[0][0] * c[0] + self.k[0][1] * c[1] + self.k[0][2] * c[2];
        let v = self.k[1][0] * c[0] + self.k[1][1] * c[1] + self.k[1][2] * c[2];
        Some([u / c[2], v / c[2]])
    }
}

/// Points on the shape's surface in mesh units (the mesh fills [-1, 1]^3), `None` for shapes
/// whose silhouette is not the hull of its points.
fn outline_points(shape: &str) -> Option<Vec<[f64; 3]>> {
    let ring = |z: f64, n: usize| {
        (0..n).map(move |i| {
            let a = i as f64 / n as f64 * std::f64::consts::TAU;
            [a.cos(), a.sin(), z]
        })
    };
    Some(match shape {
        "cube" => (0..8)
            .map(|i| {
                let s = |b: usize| if i >> b & 1 == 1 { 1.0 } else { -1.0 };
                [s(0), s(1), s(2)]
            })
            .collect(),
        "cylinder" => ring(-1.0, 64).chain(ring(1.0, 64)).collect(),
        "sphere" => {
            // A Fibonacci lattice: evenly spread points.
            let n = 600;
            let golden = std::f64::consts::PI * (3.0 - 5f64.sqrt());
            (0..n)
                .map(|i| {
                    let z = 1.0 - 2.0 * (i as f64 + 0.5) / n as f64;
                    let r = (1.0 - z * z).sqrt();
                    let a = golden * i as f64;
                    [r * a.cos(), r * a.sin(), z]
                })
                .collect()
        }
        _ => return None,
    })
}

/// Area in pixels of the unoccluded silhouette of an object at `coords` (z = its scale),
/// rotated `rotation_deg` about z, in an image of `size`; `None` for shapes not modelled.
pub fn silhouette_area(
    cam: &Camera,
    size: (u32, u32),
    shape: &str,
    coords: [f64; 3],
    rotation_deg: f64,
) -> Option<f64> {
    let scale = coords[2];
    if scale.is_nan() || scale <= 0.0 {
        return None;
    }
    let (s, c) = rotation_deg.to_radians().sin_cos();
    let pts: Vec<[f64; 2]> = outline_points(shape)?
        .into_iter()
        .map(|[x, y, z]| {
            let (x, y) = (c * x - s * y, s * x + c * y);
            cam.project([
                coords[0] + scale * x,
                coords[1] + scale * y,
                coords[2] + scale * z,
            ])
        })
        .collect::<Option<_>>()?;
    let hull = convex_hull(pts);
    let clipped = clip_to_rect(&hull, f64::from(size.0), f64::from(size.1));
    Some(area(&clipped))
}

/// Andrew's monotone chain, counter-clockwise (in y-down pixels: clockwise on screen).
fn convex_hull(mut p: Vec<[f64; 2]>) -> Vec<[f64; 2]> {
    p.sort_by(|a, b| a[0].total_cmp(&b[0]).then(a[1].total_cmp(&b[1])));
    p.dedup();
    if p.len() < 3 {
        return p;
    }
    let cross = |o: [f64; 2], a: [f64; 2], b: [f64; 2]| {
        (a[0] - o[0]) * (b[1] - o[1]) - (a[1] - o[1]) * (b[0] - o[0])
    };
    let mut h: Vec<[f64; 2]> = Vec::with_capacity(2 * p.len());
    for pass in 0..2 {
        let start = h.len();
        let iter: Box<dyn Iterator<Item = &[f64; 2]>> = if pass == 0 {
            Box::new(p.iter())
        } else {
            Box::new(p.iter().rev())
        };
        for &q in iter {
            while h.len() >= start + 2 && cross(h[h.len() - 2], h[h.len() - 1], q) <= 0.0 {
                h.pop();
            }
            h.push(q);
        }
        h.pop();
    }
    h
}

/// Sutherland-Hodgman clipping of a convex polygon to `[0, w] x [0, h]`.
fn clip_to_rect(poly: &[[f64; 2]], w: f64, h: f64) -> Vec<[f64; 2]> {
    let mut out = poly.to_vec();
    // (axis, bound, keep when coordinate <= bound?)
    for (axis, bound, below) in [(0, 0.0, false), (0, w, true), (1, 0.0, false), (1, h, true)] {
        let inside = |p: [f64; 2]| {
            if below {
                p[axis] <= bound
            } else {
                p[axis] >= bound
            }
        };
        let input = std::mem::take(&mut out);
        for i in 0..input.len() {
            let (a, b) = (input[i], input[(i + 1) % input.len()]);
            let cut = |a: [f64; 2], b: [f64; 2]| {
                let t = (bound - a[axis]) / (b[axis] - a[axis]);
                [a[0] + t * (b[0] - a[0]), a[1] + t * (b[1] - a[1])]
            };
            match (inside(a), inside(b)) {
                (true, true) => out.push(b),
                (true, false) => out.push(cut(a, b)),
                (false, true) => {
                    out.push(cut(a, b));
                    out.push(b);
                }
                (false, false) => {}
            }
        }
    }
    out
}

/// Shoelace area.
fn area(poly: &[[f64; 2]]) -> f64 {
    let n = poly.len();
    (0..n)
        .map(|i| {
            let (a, b) = (poly[i], poly[(i + 1) % n]);
            a[0] * b[1] - b[0] * a[1]
        })
        .sum::<f64>()
        .abs()
        / 2.0
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn hull_and_clip_of_a_square() {
        let sq = convex_hull(vec![
            [0.0, 0.0],
            [2.0, 0.0],
            [2.0, 2.0],
            [0.0, 2.0],
            [1.0, 1.0],
        ]);
        assert_eq!(sq.len(), 4);
        assert!((area(&sq) - 4.0).abs() < 1e-12);
        // Half of it lies right of x = 1.
        assert!((area(&clip_to_rect(&sq, 1.0, 10.0)) - 2.0).abs() < 1e-12);
    }

    #[test]
    fn a_sphere_facing_the_camera_covers_pi_r_squared() {
        // Camera at the origin looking along +z (OpenCV axes = world axes), f = 100 px.
        let cam = Camera {
            k: [[100.0, 0.0, 50.0], [0.0, 100.0, 50.0], [0.0, 0.0, 1.0]],
            e: [
                [1.0, 0.0, 0.0, 0.0],
                [0.0, 1.0, 0.0, 0.0],
                [0.0, 0.0, 1.0, 9.0],
                [0.0, 0.0, 0.0, 1.0],
            ],
            location: [0.0; 3],
        };
        // Radius 1 at distance 10: a circle of radius 100/sqrt(99) px (the tangent cone).
        let a = silhouette_area(&cam, (100, 100), "sphere", [0.0, 0.0, 1.0], 0.0).unwrap();
        let r = 100.0 / 99f64.sqrt();
        let expect = std::f64::consts::PI * r * r;
        assert!((a / expect - 1.0).abs() < 0.02, "{a} vs {expect}");
        assert!(silhouette_area(&cam, (100, 100), "monkey", [0.0, 0.0, 1.0], 0.0).is_none());
    }

    #[test]
    fn projection_puts_the_axis_at_the_principal_point_and_nothing_behind() {
        let cam = Camera {
            k: [[100.0, 0.0, 50.0], [0.0, 100.0, 40.0], [0.0, 0.0, 1.0]],
            e: [
                [1.0, 0.0, 0.0, 0.0],
                [0.0, 1.0, 0.0, 0.0],
                [0.0, 0.0, 1.0, 0.0],
                [0.0, 0.0, 0.0, 1.0],
            ],
            location: [0.0; 3],
        };
        assert_eq!(cam.project([0.0, 0.0, 5.0]), Some([50.0, 40.0]));
        // One metre right and down at 10 m: 10 px right and down of the centre.
        assert_eq!(cam.project([1.0, 1.0, 10.0]), Some([60.0, 50.0]));
        assert_eq!(cam.project([0.0, 0.0, -1.0]), None);
        // A cube reaching back to the camera's plane has no silhouette (corners behind the
        // camera); moved 5 m in front of it, it has one.
        assert!(silhouette_area(&cam, (100, 80), "cube", [0.0, 0.0, 1.0], 0.0).is_none());
        let mut back = cam.clone();
        back.e[2][3] = 5.0;
        assert!(silhouette_area(&back, (100, 80), "cube", [0.0, 0.0, 1.0], 0.0).unwrap() > 0.0);
    }
}
