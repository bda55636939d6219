//! The sampler: one seeded, pure function from (config, request) to a scene file.

use crate::camera::{directions, look_at_matrix, normalize, track_matrix};
use crate::config::{Config, Placement};
use crate::names::{stem, Split};
use crate::rng::{below, choose, scene_rng, uniform, unit, Purpose, SceneRng};
use crate::scene_file::{
    AreaLight, Backdrop, Camera, MaterialInstance, SceneFile, SceneObject, Sun, SCENE_FORMAT,
    SCENE_VERSION,
};

/// Which image to sample.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct SampleRequest {
    /// Run seed.
    pub seed: u64,
    /// Image index, `0..total`.
    pub index: u64,
    /// Visibility retry number (0 first); a new attempt redraws everything but the object count.
    pub attempt: u32,
    /// Size of the whole dataset, which fixes the splits.
    pub total: u64,
}

/// Why a scene could not be sampled.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum SampleError {
    /// The index is outside the dataset.
    #[error("image index `{index}` is outside the dataset of `{total}` images\nhint: pass a total larger than the last index")]
    IndexOutOfRange {
        /// Requested index.
        index: u64,
        /// Dataset size.
        total: u64,
    },
    /// The request cannot be met whatever the draws (an area bound), so nothing was tried.
    #[error("cannot place {count} objects of size at least {min_size} with min-dist {min_dist} in the {side}x{side} area: at most {bound} fit (an area bound), so nothing was tried\nhint: lower the maximum of `objects.count`, use smaller sizes or a smaller `min_dist`, or enlarge `placement.area`")]
    Infeasible {
        /// Objects requested.
        count: u32,
        /// Smallest size scale of the config.
        min_size: f64,
        /// Spacing rule.
        min_dist: f64,
        /// Side of the placement square.
        side: f64,
        /// Upper bound on how many objects fit.
        bound: u32,
    },
    /// Placement ran out of restarts.
    #[error("cannot place {count} objects of size up to {max_size} with min-dist {min_dist} and margin {margin} in the {side}x{side} area after {restarts} restarts (image `{index}`, attempt {attempt})\nhint: lower the maximum of `objects.count`, use smaller sizes, lower `min_dist` or `margin`, or raise `placement.max_restarts`")]
    PlacementExhausted {
        /// Image index.
        index: u64,
        /// Visibility attempt.
        attempt: u32,
        /// Objects requested.
        count: u32,
        /// Largest size scale of the config.
        max_size: f64,
        /// Spacing rule.
        min_dist: f64,
        /// Margin rule.
        margin: f64,
        /// Side of the placement square.
        side: f64,
        /// Restarts made.
        restarts: u32,
    },
}

/// The object count of image `index`: drawn from its own stream, so it is the same for every
/// visibility attempt (the reference keeps it across retries).
pub fn object_count(config: &Config, seed: u64, index: u64) -> u32 {
    let mut rng = scene_rng(seed, config.layout_stream(), 0, Purpose::Count, index);
    let [lo, hi] = config.objects.count;
    lo + below(&mut rng, (hi - lo + 1) as usize) as u32
}

/// Upper bound on how many objects can ever be placed, whatever the draws.
///
/// Any two centres end at least `d = r_new + r_old + min_dist` apart, with `r_new` at least
/// the smallest size and `r_old` at least the smallest recorded radius (a cube's is divided by
/// sqrt 2). Oler's inequality bounds the points with mutual distance >= d in a square of side
/// `L`: n <= 2/sqrt(3) (L/d)^2 + 2 L/d + 1.
pub fn max_objects_bound(config: &Config) -> u32 {
    let p = &config.base.placement;
    let min_size = min_size(config);
    let cubes = p.cube_radius_quirk && config.objects.shapes.iter().any(|s| s == "cube");
    let old = if cubes {
        min_size / std::f64::consts::SQRT_2
    } else {
        min_size
    };
    let d = min_size + old + p.min_dist;
    let l = (p.area[1] - p.area[0]) / d;
    let bound = 2.0 / 3f64.sqrt() * l * l + 2.0 * l + 1.0;
    bound.floor().min(f64::from(u32::MAX)) as u32
}

/// Fail when the largest object count of `config` exceeds [`max_objects_bound`]: such a
/// config can never sample its largest scenes, so a run should stop before it starts.
pub fn check_feasible(config: &Config) -> Result<(), SampleError> {
    count_fits(config, config.objects.count[1])
}

/// Fail when `count` objects of `config` can never be placed (more than
/// [`max_objects_bound`]).
fn count_fits(config: &Config, count: u32) -> Result<(), SampleError> {
    let p = &config.base.placement;
    let bound = max_objects_bound(config);
    if count > bound {
        return Err(SampleError::Infeasible {
            count,
            min_size: min_size(config),
            min_dist: p.min_dist,
            side: p.area[1] - p.area[0],
            bound,
        });
    }
    Ok(())
}

fn min_size(config: &Config) -> f64 {
    config
        .objects
        .sizes
        .iter()
        .map(|s| s.scale)
        .fold(f64::INFINITY, f64::min)
}

fn max_size(config: &Config) -> f64 {
    config
        .objects
        .sizes
        .iter()
        .map(|s| s.scale)
        .fold(0.0, f64::max)
}

fn jitter(rng: &mut SceneRng, p: [f64; 3], amount: f64) -> [f64; 3] {
    p.map(|v| v + uniform(rng, -amount, amount))
}

/// Sample the scene of one image. Pure and deterministic in `(config, req)`.
pub fn sample(config: &Config, req: &SampleRequest) -> Result<SceneFile, SampleError> {
    if req.index >= req.total {
        return Err(SampleError::IndexOutOfRange {
            index: req.index,
            total: req.total,
        });
    }
    let p = &config.base.placement;
    let count = object_count(config, req.seed, req.index);
    count_fits(config, count)?;

    let mut rng = scene_rng(
        req.seed,
        config.layout_stream(),
        req.attempt,
        Purpose::Layout,
        req.index,
    );
    let base = &config.base;

    // Camera and lights first: the margin rule needs the jittered camera's directions.
    let cam = &base.camera;
    let cam_loc = jitter(&mut rng, cam.location, cam.jitter);
    let camera = Camera {
        location: cam_loc,
        look_at: cam.look_at,
        matrix_world: look_at_matrix(cam_loc, cam.look_at),
        focal_length_mm: cam.focal_length_mm,
        sensor_width_mm: cam.sensor_width_mm,
        clip_start: cam.clip_start,
        clip_end: cam.clip_end,
    };
    let lights: Vec<AreaLight> = base
        .lights
        .iter()
        .map(|l| {
            let loc = jitter(&mut rng, l.location, l.jitter);
            AreaLight {
                name: l.name.clone(),
                location: loc,
                matrix_world: look_at_matrix(loc, l.look_at),
                size: l.size,
                energy: l.energy,
                color: l.color,
            }
        })
        .collect();
    let sun_dir = normalize(base.sun.direction);
    let sun = Sun {
        direction: sun_dir,
        matrix_world: track_matrix([0.0; 3], sun_dir),
        strength: base.sun.strength,
        angle: base.sun.angle,
    };

    // Materials of the scene: drawn from their own stream, so the layout (camera, lights,
    // shapes, sizes, positions, rotations) is the same whatever catalogue they come from.
    let mut mrng = scene_rng(
        req.seed,
        config.layout_stream(),
        req.attempt,
        Purpose::Material,
        req.index,
    );
    let scene_material = config
        .same_material
        .then(|| choose(&mut mrng, &config.objects.materials).clone());
    let bg_name = match &scene_material {
        Some(m) => m.clone(),
        None => choose(&mut mrng, &config.background.materials).clone(),
    };
    let backdrop = Backdrop {
        profile: base.backdrop.profile.clone(),
        y_range: base.backdrop.y_range,
        rotation_z: base.backdrop.rotation_z,
        material: MaterialInstance {
            name: bg_name,
            random: unit(&mut mrng),
            color_name: None,
            color: None,
            displacement: config.background.displacement,
            scale: config.background.scale,
        },
    };

    let dirs = directions(&camera);
    let margin_dirs = [dirs.left, dirs.right, dirs.front, dirs.behind];
    let layout =
        place(config, p, count, &margin_dirs, &mut rng).ok_or(SampleError::PlacementExhausted {
            index: req.index,
            attempt: req.attempt,
            count,
            max_size: max_size(config),
            min_dist: p.min_dist,
            margin: p.margin,
            side: p.area[1] - p.area[0],
            restarts: p.max_restarts,
        })?;

    let objects = layout
        .into_iter()
        .map(|(shape, size, x, y)| {
            let rotation_deg = uniform(&mut rng, 0.0, 360.0);
            let name = match &scene_material {
                Some(m) => m.clone(),
                None => choose(&mut mrng, &config.objects.materials).clone(),
            };
            let (color_name, color) = if config.objects.colors.is_empty() {
                (None, None)
            } else {
                let c = choose(&mut mrng, &config.objects.colors);
                (Some(c.name.clone()), Some(c.linear()))
            };
            let size = &config.objects.sizes[size];
            SceneObject {
                shape: config.objects.shapes[shape].clone(),
                size: size.name.clone(),
                scale: size.scale,
                location: [x, y, size.scale],
                rotation_deg,
                material: MaterialInstance {
                    displacement: config.objects.displacement_for(&name),
                    name,
                    random: unit(&mut mrng),
                    color_name,
                    color,
                    // One material on everything (`camo`): the backdrop's texture scale too,
                    // so objects and backdrop show the texture at one world scale (texture
                    // coordinates are world units on both; `blender_scripts/materials.py`).
                    scale: scene_material.as_ref().and(config.background.scale),
                },
            }
        })
        .collect();

    Ok(SceneFile {
        format: SCENE_FORMAT.to_string(),
        version: SCENE_VERSION,
        variant: config.name.clone(),
        index: req.index,
        split: Split::of(config.splits, req.index, req.total)
            .name()
            .to_string(),
        seed: req.seed,
        layout_stream: config.layout_stream().to_string(),
        attempt: req.attempt,
        stem: stem(&config.name, req.index),
        render: base.render.clone(),
        passes: base.passes.clone(),
        camera,
        lights,
        sun,
        backdrop,
        objects,
    })
}

/// CLEVR's placement: per object a size and shape, then up to `tries_per_object` positions
/// until one keeps the spacing and margin rules against every placed object; when an object
/// runs out of tries everything is removed and placement restarts, at most `max_restarts`
/// times. Returns `(shape index, size index, x, y)` per object.
fn place(
    config: &Config,
    p: &Placement,
    count: u32,
    dirs: &[[f64; 3]; 4],
    rng: &mut SceneRng,
) -> Option<Vec<(usize, usize, f64, f64)>> {
    let mut out = Vec::with_capacity(count as usize);
    // (x, y, recorded radius) of the objects placed so far.
    let mut placed: Vec<(f64, f64, f64)> = Vec::with_capacity(count as usize);
    'restart: for _ in 0..p.max_restarts {
        out.clear();
        placed.clear();
        for _ in 0..count {
            let size = below(rng, config.objects.sizes.len());
            let shape = below(rng, config.objects.shapes.len());
            let r = config.objects.sizes[size].scale;
            let mut found = None;
            for _ in 0..p.tries_per_object {
                let x = uniform(rng, p.area[0], p.area[1]);
                let y = uniform(rng, p.area[0], p.area[1]);
                if fits(x, y, r, &placed, p, dirs) {
                    found = Some((x, y));
                    break;
                }
            }
            let Some((x, y)) = found else {
                continue 'restart;
            };
            let recorded = if p.cube_radius_quirk && config.objects.shapes[shape] == "cube" {
                r / std::f64::consts::SQRT_2
            } else {
                r
            };
            placed.push((x, y, recorded));
            out.push((shape, size, x, y));
        }
        return Some(out);
    }
    None
}

/// The spacing and margin rules of a new object at `(x, y)` with radius `r` against every
/// placed one. `dirs` are left, right, front, behind; right and front are exact negations of
/// left and behind, so `0 < m < margin` along a direction or its opposite is `0 < |m| < margin`.
fn fits(
    x: f64,
    y: f64,
    r: f64,
    placed: &[(f64, f64, f64)],
    p: &Placement,
    dirs: &[[f64; 3]; 4],
) -> bool {
    let (left, behind) = (dirs[0], dirs[3]);
    placed.iter().all(|&(xx, yy, rr)| {
        let (dx, dy) = (x - xx, y - yy);
        let ml = (dx * left[0] + dy * left[1]).abs();
        let mb = (dx * behind[0] + dy * behind[1]).abs();
        if (0.0 < ml && ml < p.margin) || (0.0 < mb && mb < p.margin) {
            return false;
        }
        (dx * dx + dy * dy).sqrt() - r - rr >= p.min_dist
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn req(index: u64) -> SampleRequest {
        SampleRequest {
            seed: 7,
            index,
            attempt: 0,
            total: 100,
        }
    }

    #[test]
    fn same_request_same_scene_and_attempts_differ_but_keep_the_count() {
        let c = Config::builtin("full").unwrap();
        let a = sample(&c, &req(5)).unwrap();
        assert_eq!(a, sample(&c, &req(5)).unwrap());
        let b = sample(
            &c,
            &SampleRequest {
                attempt: 1,
                ..req(5)
            },
        )
        .unwrap();
        assert_ne!(a.camera, b.camera);
        assert_eq!(a.objects.len(), b.objects.len());
    }

    #[test]
    fn index_outside_the_dataset_is_an_error() {
        let c = Config::builtin("full").unwrap();
        let e = sample(&c, &req(100)).unwrap_err();
        assert!(matches!(e, SampleError::IndexOutOfRange { .. }));
    }

    #[test]
    fn area_bound_admits_the_reference_and_rejects_the_absurd() {
        let mut c = Config::builtin("full").unwrap();
        assert!(max_objects_bound(&c) >= 10);
        c.objects.count = [100, 100];
        let e = sample(&c, &req(0)).unwrap_err();
        assert!(
            matches!(e, SampleError::Infeasible { count: 100, .. }),
            "{e}"
        );
    }

    #[test]
    fn camo_objects_take_the_backdrops_texture_scale_and_full_objects_none() {
        // `camo` has one material on everything: objects and backdrop must show its texture
        // at one world scale, so the objects' copy carries the backdrop's `scale` (2).
        let c = Config::builtin("camo").unwrap();
        assert_eq!(c.background.scale, Some(2.0));
        for i in 0..5 {
            let s = sample(&c, &req(i)).unwrap();
            assert_eq!(s.backdrop.material.scale, Some(2.0));
            for o in &s.objects {
                assert_eq!(o.material.name, s.backdrop.material.name);
                assert_eq!(o.material.scale, s.backdrop.material.scale, "index {i}");
            }
        }
        // Variants with their own object materials keep the recipe's scale on objects.
        let s = sample(&Config::builtin("full").unwrap(), &req(3)).unwrap();
        assert!(s.objects.iter().all(|o| o.material.scale.is_none()));
    }

    #[test]
    fn layouts_do_not_depend_on_the_material_catalogue() {
        // The controlled comparison (built-in vs user library): another material list must
        // leave camera, lights, shapes, sizes, positions and rotations as they were.
        for variant in ["full", "camo", "vbg"] {
            let a = Config::builtin(variant).unwrap();
            let mut b = a.clone();
            b.objects.materials = vec!["plain".into()];
            b.background.materials = vec!["plain".into()];
            for i in 0..10 {
                let (x, y) = (sample(&a, &req(i)).unwrap(), sample(&b, &req(i)).unwrap());
                assert_eq!(
                    (&x.camera, &x.lights),
                    (&y.camera, &y.lights),
                    "{variant} {i}"
                );
                assert_eq!(x.objects.len(), y.objects.len());
                for (o, p) in x.objects.iter().zip(&y.objects) {
                    assert_eq!(
                        (&o.shape, o.scale, o.location, o.rotation_deg),
                        (&p.shape, p.scale, p.location, p.rotation_deg)
                    );
                    assert_eq!(p.material.name, "plain");
                    // The instance values stay too: only the name changed.
                    assert_eq!(o.material.random, p.material.random);
                }
            }
        }
    }
}
