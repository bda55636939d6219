//! The measurement: for each scene its reference (cached) and first-sample render, then every
//! rung, each compared with them.

use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::{bail, Context, Result};
use clevrtex_materials::Catalogue;
use clevrtex_render::exr_io::Channels;
use clevrtex_render::{Mode, RenderReply, Worker};
use clevrtex_scene::quality::Sampling;
use clevrtex_scene::SceneFile;

use crate::ladder::Setting;
use crate::metrics::{self, Errors};
use crate::scenes::{timeout_for, with_sampling, BenchScene, REFERENCE_SEED};

/// A Blender session to run worker requests on: the command line hands in its own (restarts,
/// Ctrl-C and its messages are the command's).
pub trait Render {
    /// Run `call` on the session's worker, with the command's restarts.
    fn request(&mut self, call: &mut dyn FnMut(&mut Worker) -> WorkerResult)
        -> Result<RenderReply>;
}

/// What one render request to a worker returns.
pub type WorkerResult = clevrtex_render::Result<RenderReply>;

/// What the measurement is doing, for the command to print.
#[derive(Debug)]
pub enum Event<'a> {
    /// A scene's reference was found in the cache.
    ReferenceCached {
        /// The scene's label.
        scene: &'a str,
        /// The cache folder.
        dir: &'a Path,
    },
    /// A scene's reference is being rendered.
    ReferenceRendering {
        /// The scene's label.
        scene: &'a str,
        /// Its samples.
        samples: u32,
    },
    /// A scene's reference was rendered.
    ReferenceRendered {
        /// The scene's label.
        scene: &'a str,
        /// Wall time, seconds.
        wall_s: f64,
        /// Cycles' render time, seconds.
        cycles_s: f64,
    },
    /// One rung of one scene was measured.
    Measured {
        /// Rungs measured so far (this one included).
        done: usize,
        /// Rungs to measure in all.
        total: usize,
        /// `<scene> <rung>`.
        label: &'a str,
        /// Wall time, seconds.
        wall_s: f64,
        /// Its relative error.
        rel_error: f64,
        /// The bridge's phases of the render request (CPU seconds shown).
        phases: clevrtex_render::BridgePhases,
    },
}

/// The progress line the command prints for each event (`clevrtex bench render`, on stderr).
impl std::fmt::Display for Event<'_> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Event::ReferenceCached { scene, dir } => {
                write!(f, "[{scene}] reference cached in `{}`", dir.display())
            }
            Event::ReferenceRendering { scene, samples } => {
                write!(
                    f,
                    "[{scene}] rendering the reference ({samples} samples) ..."
                )
            }
            Event::ReferenceRendered {
                scene,
                wall_s,
                cycles_s,
            } => write!(
                f,
                "[{scene}] reference took {wall_s:.1} s (cycles {cycles_s:.1} s)"
            ),
            Event::Measured {
                done,
                total,
                label,
                wall_s,
                rel_error,
                phases,
            } => {
                write!(
                    f,
                    "[{done}/{total}] {label}: {wall_s:.2} s, rel error {rel_error:.4}"
                )?;
                let parts: Vec<String> = phases
                    .named()
                    .iter()
                    .filter(|(_, t)| t.cpu_s > 0.0)
                    .map(|(name, t)| format!("{name} {:.2}", t.cpu_s))
                    .collect();
                if !parts.is_empty() {
                    write!(f, "; bridge CPU s: {}", parts.join(", "))?;
                }
                Ok(())
            }
        }
    }
}

/// One measured (setting, scene) pair.
#[derive(Debug, Clone)]
pub struct Row {
    /// The Blender version that rendered it (empty in CSVs of older versions).
    pub blender: String,
    /// The scene's label.
    pub scene: String,
    /// The scene's variant.
    pub variant: String,
    /// Image width.
    pub width: u32,
    /// Image height.
    pub height: u32,
    /// The rung.
    pub setting: Setting,
    /// Wall time of the render request, seconds.
    pub wall_s: f64,
    /// Cycles' render time, seconds.
    pub cycles_s: f64,
    /// CPU seconds of the Blender process during that render, all threads (NaN in CSVs of
    /// older versions): the cost compared across Blenders, steadier than `cycles_s` (wall
    /// time) when other jobs share the machine.
    pub cycles_cpu_s: f64,
    /// Its error against the reference.
    pub errors: Errors,
    /// Mean linear value of the scene's reference (its Blender's own; NaN in CSVs of older
    /// versions): brightness compared across Blenders.
    pub reference_mean: f64,
}

/// The sizes of a bench run, defaults resolved (`--quick` or not).
#[derive(Debug, Clone, Copy)]
pub struct Plan {
    /// Number of scenes.
    pub scenes: usize,
    /// Image width.
    pub width: u32,
    /// Image height.
    pub height: u32,
    /// Fixed samples of the references.
    pub reference_samples: u32,
}

/// The most scenes `--scenes` takes (`clevrtex bench render --help`).
pub const MAX_SCENES: usize = 1024;

impl Plan {
    /// The sizes given (`None`: the default, smaller with `quick`); each must be positive.
    pub fn new(
        quick: bool,
        scenes: Option<usize>,
        width: Option<u32>,
        height: Option<u32>,
        reference_samples: Option<u32>,
    ) -> anyhow::Result<Plan> {
        let plan = Plan {
            scenes: scenes.unwrap_or(if quick { 2 } else { 8 }),
            width: width.unwrap_or(if quick { 160 } else { 320 }),
            height: height.unwrap_or(if quick { 120 } else { 240 }),
            reference_samples: reference_samples.unwrap_or(if quick { 1024 } else { 4096 }),
        };
        if plan.scenes == 0 || plan.width == 0 || plan.height == 0 || plan.reference_samples == 0 {
            bail!("`--scenes`, `--width`, `--height` and `--reference-samples` must be positive\nhint: e.g. `clevrtex bench render --quick`");
        }
        if plan.scenes > MAX_SCENES {
            bail!(
                "`--scenes {}` is over {MAX_SCENES}\nhint: the bench compares a few scenes; pass 1 to {MAX_SCENES}",
                plan.scenes
            );
        }
        Ok(plan)
    }

    /// The first rung with no fewer samples than the references (its error means nothing).
    pub fn oversampled<'s>(&self, settings: &'s [Setting]) -> Option<&'s Setting> {
        settings
            .iter()
            .find(|s| s.sampling.samples >= self.reference_samples)
    }
}

/// The decoded outputs of one render.
struct Outputs {
    rgb: Vec<f32>,
    srgb: Vec<u8>,
    mask: Vec<f32>,
    depth: Vec<f32>,
    mean: f64,
}

fn read_outputs(dir: &Path) -> anyhow::Result<Outputs> {
    let ch = Channels::read(&dir.join("passes.exr"))?;
    let (r, g, b) = (
        ch.get("ViewLayer.Combined.R")?,
        ch.get("ViewLayer.Combined.G")?,
        ch.get("ViewLayer.Combined.B")?,
    );
    let rgb: Vec<f32> = (0..r.len()).flat_map(|i| [r[i], g[i], b[i]]).collect();
    let png = dir.join("rgb.png");
    let srgb = image::open(&png)
        .with_context(|| format!("cannot read `{}`", png.display()))?
        .to_rgb8()
        .into_raw();
    Ok(Outputs {
        mean: metrics::mean(&rgb),
        rgb,
        srgb,
        mask: ch.get("ViewLayer.IndexOB.X")?.to_vec(),
        depth: ch.get("ViewLayer.Depth.Z")?.to_vec(),
    })
}

fn compare(got: &Outputs, reference: &Outputs, first_sample: &Outputs) -> Errors {
    let rmse = metrics::rmse(&got.rgb, &reference.rgb);
    Errors {
        rmse_linear: rmse,
        rel_error: metrics::ratio(rmse, reference.mean),
        bias: metrics::ratio(got.mean - reference.mean, reference.mean),
        psnr_srgb: metrics::psnr_u8(&got.srgb, &reference.srgb),
        mask_equal: metrics::bits_equal(&got.mask, &first_sample.mask),
        depth_equal: metrics::bits_equal(&got.depth, &first_sample.depth),
    }
}

/// What one render took, seconds.
struct Took {
    /// The request, as this process saw it.
    wall_s: f64,
    /// Cycles' render (wall time, as the bridge measured it).
    cycles_s: f64,
    /// CPU time of the Blender process during the render (NaN from older bridges).
    cycles_cpu_s: f64,
    /// The bridge's phases of the request.
    phases: clevrtex_render::BridgePhases,
}

/// Render `scene` into `dir` (created, emptied of old outputs); what it took.
fn render_into(
    blender: &mut dyn Render,
    label: &str,
    scene: &SceneFile,
    dir: &Path,
) -> anyhow::Result<Took> {
    std::fs::create_dir_all(dir).with_context(|| {
        format!(
            "cannot create `{}`\nhint: pass a writable `--out`",
            dir.display()
        )
    })?;
    for f in ["rgb.png", "passes.exr"] {
        let _ = std::fs::remove_file(dir.join(f));
    }
    let path = dir.join("scene.json");
    clevrtex_dataset::atomic::write(&path, clevrtex_scene::to_pretty_json(scene)?.as_bytes())
        .with_context(|| format!("cannot write `{}`", path.display()))?;
    let started = Instant::now();
    let timeout = timeout_for(scene);
    let reply =
        blender.request(&mut |w| w.render_labelled(label, &path, Mode::Final, dir, timeout))?;
    Ok(Took {
        wall_s: started.elapsed().as_secs_f64(),
        cycles_s: reply.timings.render_s,
        cycles_cpu_s: reply.timings.render_cpu_s.unwrap_or(f64::NAN),
        phases: reply.timings.phases,
    })
}

/// Where the rungs' renders go in output folder `out`: `out/runs` for one Blender; with
/// several, `out/runs/<place>-<version>` for the one at `place` in the list (the version is
/// Blender's word: only its ASCII letters, digits and dots make the name, the rest `_`).
pub fn runs_dir(out: &Path, place: Option<usize>, blender_version: &str) -> PathBuf {
    let runs = out.join("runs");
    let Some(i) = place else {
        return runs;
    };
    let v: String = blender_version
        .chars()
        .map(|c| {
            if c.is_ascii_alphanumeric() || c == '.' {
                c
            } else {
                '_'
            }
        })
        .collect();
    runs.join(format!("{i}-{v}"))
}

/// Where everything the measurement needs comes from.
pub struct Bench<'a> {
    /// The Blender.
    pub blender: &'a mut dyn Render,
    /// The material catalogue (the recipes of a scene's materials key its reference).
    pub catalogue: &'a Catalogue,
    /// The Blender's version (keys the references).
    pub blender_version: &'a str,
    /// Output folder: `references/` goes here (shared: keyed by the Blender version).
    pub out: &'a Path,
    /// Where each rung's render goes (`OUT/runs`, or one folder per Blender when several).
    pub runs: &'a Path,
    /// Told what is going on.
    pub on_event: &'a mut dyn FnMut(Event),
}

impl Bench<'_> {
    /// Measure every rung of `settings` on every scene: one row per (scene, rung), in order.
    pub fn measure(
        &mut self,
        plan: &Plan,
        scenes: &[BenchScene],
        settings: &[Setting],
    ) -> anyhow::Result<Vec<Row>> {
        let total = scenes.len() * settings.len();
        let mut rows = Vec::with_capacity(total);
        for (si, bs) in scenes.iter().enumerate() {
            let (reference, ref_dir) = self.reference(bs, plan.reference_samples)?;
            let geometry = self.first_sample(bs, &ref_dir)?;
            for setting in settings {
                let (took, errors) = self.rung(si, bs, setting, &reference, &geometry)?;
                let wall_s = took.wall_s;
                (self.on_event)(Event::Measured {
                    done: rows.len() + 1,
                    total,
                    label: &format!("{} {}", bs.label, setting.label),
                    wall_s,
                    rel_error: errors.rel_error,
                    phases: took.phases,
                });
                rows.push(Row {
                    blender: self.blender_version.to_string(),
                    scene: bs.label.clone(),
                    variant: bs.scene.variant.clone(),
                    width: plan.width,
                    height: plan.height,
                    setting: setting.clone(),
                    wall_s,
                    cycles_s: took.cycles_s,
                    cycles_cpu_s: took.cycles_cpu_s,
                    errors,
                    reference_mean: reference.mean,
                });
            }
        }
        Ok(rows)
    }

    /// The scene's reference from the cache, or rendered into it; and the cache folder.
    fn reference(
        &mut self,
        bs: &BenchScene,
        ref_samples: u32,
    ) -> anyhow::Result<(Outputs, PathBuf)> {
        let mut ref_scene = with_sampling(
            &bs.scene,
            &Sampling {
                samples: ref_samples,
                ..Sampling::ORIGINAL
            },
        );
        // Another Cycles seed: with the rungs' seed the reference would reuse their first
        // samples, and a rung's error would shrink by sqrt(1 - samples / reference samples).
        ref_scene.render.cycles_seed = REFERENCE_SEED;
        let ref_json = clevrtex_scene::to_pretty_json(&ref_scene)?;
        // Only the recipes of the materials this scene uses: editing another material of the
        // catalogue must not throw away hours of references. (Bridge script changes are not
        // tracked: delete `OUT/references` after changing how materials are built.)
        let used: Vec<&str> = std::iter::once(bs.scene.backdrop.material.name.as_str())
            .chain(bs.scene.objects.iter().map(|o| o.material.name.as_str()))
            .collect();
        let recipes = self.catalogue.resolved_json_for(used.iter().copied());
        // A user material's recipe names its files, not their contents: its content hash
        // (the `.blend` and every image) is in the key too, so a texture edited in place
        // renders a new reference. Built-in-only scenes keep the keys they had.
        let mut user: Vec<&str> = used
            .iter()
            .filter_map(|n| self.catalogue.get(n))
            .filter(|m| m.set == clevrtex_materials::Set::User)
            .map(|m| m.hash.as_str())
            .collect();
        user.sort_unstable();
        user.dedup();
        let user = user.join(",");
        let mut parts = vec![
            ref_json.as_bytes(),
            recipes.as_bytes(),
            self.blender_version.as_bytes(),
        ];
        if !user.is_empty() {
            parts.push(user.as_bytes());
        }
        let key = clevrtex_materials::content_hash(&parts);
        let ref_dir = self.out.join("references").join(format!("{key:016x}"));
        let reference = match read_outputs(&ref_dir) {
            Ok(r) => {
                (self.on_event)(Event::ReferenceCached {
                    scene: &bs.label,
                    dir: &ref_dir,
                });
                r
            }
            Err(_) => {
                (self.on_event)(Event::ReferenceRendering {
                    scene: &bs.label,
                    samples: ref_samples,
                });
                let label = format!("{} reference", bs.label);
                let took = render_into(self.blender, &label, &ref_scene, &ref_dir)?;
                (self.on_event)(Event::ReferenceRendered {
                    scene: &bs.label,
                    wall_s: took.wall_s,
                    cycles_s: took.cycles_s,
                });
                read_outputs(&ref_dir)?
            }
        };
        Ok((reference, ref_dir))
    }

    /// Mask and depth come from each pixel's first sample, so they are compared with a
    /// 1-sample render at the rungs' seed (cached beside the reference): equal means no
    /// setting changes them.
    fn first_sample(&mut self, bs: &BenchScene, ref_dir: &Path) -> anyhow::Result<Outputs> {
        let geo_dir = ref_dir.join("first-sample");
        match read_outputs(&geo_dir) {
            Ok(r) => Ok(r),
            Err(_) => {
                let geo_scene = with_sampling(
                    &bs.scene,
                    &Sampling {
                        samples: 1,
                        ..Sampling::ORIGINAL
                    },
                );
                let label = format!("{} first sample", bs.label);
                render_into(self.blender, &label, &geo_scene, &geo_dir)?;
                read_outputs(&geo_dir)
            }
        }
    }

    /// Render scene `si` at one rung into [`Bench::runs`]; what it took and its errors.
    fn rung(
        &mut self,
        si: usize,
        bs: &BenchScene,
        setting: &Setting,
        reference: &Outputs,
        geometry: &Outputs,
    ) -> anyhow::Result<(Took, Errors)> {
        let scene = with_sampling(&bs.scene, &setting.sampling);
        let dir = self.runs.join(format!("{si:02}-{}", setting.label));
        let label = format!("{} {}", bs.label, setting.label);
        let took = render_into(self.blender, &label, &scene, &dir)?;
        let errors = compare(&read_outputs(&dir)?, reference, geometry);
        Ok((took, errors))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn runs_dir_is_one_plain_folder_per_place() {
        let out = Path::new("o");
        assert_eq!(runs_dir(out, None, "3.4.1"), Path::new("o/runs"));
        assert_eq!(
            runs_dir(out, Some(1), "4.5.15 LTS"),
            Path::new("o/runs/1-4.5.15_LTS")
        );
        // Blender's answer never leaves the runs folder.
        assert_eq!(
            runs_dir(out, Some(0), "../../x/.."),
            Path::new("o/runs/0-.._.._x_..")
        );
    }
}
