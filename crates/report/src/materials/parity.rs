//! `clevrtex materials parity`: whether every Blender renders each material alike (issue 50).
//!
//! One fixed scene of the `full` variant ([`base_scene`]) is drawn again per material: as the
//! backdrop (displaced as the variants displace it, objects left out) and on every object
//! (the backdrop keeping the scene's own material) ([`scene_for`]). Each scene file is
//! rendered by each Blender through the render path of `generate` (a `render` request,
//! `clevrtex_render::material_renders::render_scene`) with the RGB, mask and depth passes,
//! and measured on the pixels of the backdrop or of the objects ([`measure`]): the mean linear
//! luminance (the look) and the mean camera depth (the relief). [`table`] sets every Blender
//! against the first and counts the materials past [`LUMINANCE_BOUND`] or [`DEPTH_BOUND`].

use std::fmt::Write as _;
use std::path::PathBuf;

use anyhow::Context;
use clevrtex_materials::Catalogue;
use clevrtex_render::exr_io::Channels;
use clevrtex_render::material_renders::{render_scene, session, RenderOptions};
use clevrtex_scene::{Config, Pass, SampleRequest, SceneFile};

/// Largest relative difference of the mean linear luminance from the first Blender's.
pub const LUMINANCE_BOUND: f64 = 0.03;
/// Largest relative difference of the mean depth from the first Blender's.
pub const DEPTH_BOUND: f64 = 0.01;
/// The variant, seed and index of the scene every material is drawn into: a `full` scene
/// with a displaced backdrop and eight objects in view.
const VARIANT: &str = "full";
const SEED: u64 = 50;
const INDEX: u64 = 59;

/// Where a material goes in the scene.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Role {
    /// The backdrop, displaced as the variant displaces it; no objects.
    Backdrop,
    /// Every object; the backdrop keeps the scene's own material.
    Object,
}

impl Role {
    /// The word the table and `--as` use.
    pub fn name(self) -> &'static str {
        match self {
            Role::Backdrop => "backdrop",
            Role::Object => "object",
        }
    }
}

/// The size and sampling of the renders.
#[derive(Debug, Clone, Copy)]
pub struct Settings {
    /// Image width, pixels (the height is 3/4 of it).
    pub width: u32,
    /// Cycles samples per pixel (fixed: no adaptive sampling, no denoising).
    pub samples: u32,
}

/// One render measured on the pixels of the material.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Figures {
    /// Mean linear luminance (Rec. 709 weights of the Combined pass).
    pub luminance: f64,
    /// Mean camera depth, metres.
    pub depth: f64,
    /// Mean linear luminance of the albedo pass (the material's base colour, noise-free): a
    /// gap here is the material's texture nodes, not its shading.
    pub albedo: f64,
    /// How many pixels.
    pub pixels: usize,
}

/// One Blender's figures: its version and, per material and role, what it rendered.
pub struct Column {
    /// The Blender's path.
    pub blender: PathBuf,
    /// Its version, as its worker reported it.
    pub version: String,
    /// `(material, role)` in the order of the run.
    pub figures: Vec<((String, Role), Figures)>,
}

/// The scene every material is drawn into, at `s`'s size and samples, with the passes the
/// measure reads; and the variant's config (for the objects' displacement).
pub fn base_scene(s: Settings) -> anyhow::Result<(Config, SceneFile)> {
    let mut config = Config::builtin(VARIANT)?;
    config.base.render.width = s.width;
    config.base.render.height = (s.width * 3 / 4).max(1);
    config.base.passes = vec![Pass::Rgb, Pass::Mask, Pass::Depth, Pass::Albedo];
    let req = SampleRequest {
        seed: SEED,
        index: INDEX,
        attempt: 0,
        total: 1000,
    };
    let mut scene = clevrtex_scene::sample(&config, &req)?;
    scene.render.samples = s.samples;
    scene.render.adaptive_threshold = None;
    scene.render.denoise = false;
    scene.render.cycles_seed = 0;
    Ok((config, scene))
}

/// `base` with material `name` in `role`.
pub fn scene_for(config: &Config, base: &SceneFile, name: &str, role: Role) -> SceneFile {
    let mut scene = base.clone();
    match role {
        Role::Backdrop => {
            scene.backdrop.material.name = name.to_string();
            scene.objects.clear();
        }
        Role::Object => {
            for o in &mut scene.objects {
                o.material.name = name.to_string();
                o.material.displacement = config.objects.displacement_for(name);
            }
        }
    }
    scene
}

/// The figures of `role`'s pixels in the passes `ch` of a render: the backdrop is object
/// index 0 at a finite depth (not the sky), an object any other index. A render with no such
/// pixel is an error (the scene did not show the material).
pub fn measure(ch: &Channels, role: Role) -> anyhow::Result<Figures> {
    let (r, g, b) = (
        ch.get("ViewLayer.Combined.R")?,
        ch.get("ViewLayer.Combined.G")?,
        ch.get("ViewLayer.Combined.B")?,
    );
    let (index, depth) = (ch.get("ViewLayer.IndexOB.X")?, ch.get("ViewLayer.Depth.Z")?);
    let (ar, ag, ab) = (
        ch.get("ViewLayer.BaseCol.R")?,
        ch.get("ViewLayer.BaseCol.G")?,
        ch.get("ViewLayer.BaseCol.B")?,
    );
    let lum_of = |r: &[f32], g: &[f32], b: &[f32], i: usize| {
        0.2126 * f64::from(r[i]) + 0.7152 * f64::from(g[i]) + 0.0722 * f64::from(b[i])
    };
    let (mut lum, mut alb, mut z, mut n) = (0.0f64, 0.0f64, 0.0f64, 0usize);
    let len = [r, g, b, ar, ag, ab, index, depth]
        .iter()
        .map(|c| c.len())
        .min()
        .unwrap_or(0);
    for i in 0..len {
        let mine = match role {
            Role::Backdrop => index[i] == 0.0 && depth[i] < 1e9,
            Role::Object => index[i] > 0.0,
        };
        if mine {
            lum += lum_of(r, g, b, i);
            alb += lum_of(ar, ag, ab, i);
            z += f64::from(depth[i]);
            n += 1;
        }
    }
    if n == 0 {
        anyhow::bail!("the render shows no {} pixel", role.name());
    }
    Ok(Figures {
        luminance: lum / n as f64,
        depth: z / n as f64,
        albedo: alb / n as f64,
        pixels: n,
    })
}

/// Render each of `names` in each of `roles` with each of `blenders` in turn (one worker per
/// Blender, `opts`'s limits), in a scratch folder removed afterwards; `progress` gets a line
/// per render.
pub fn run(
    cat: &Catalogue,
    names: &[&str],
    roles: &[Role],
    blenders: &[PathBuf],
    opts: &RenderOptions,
    s: Settings,
    progress: &mut dyn FnMut(String),
) -> anyhow::Result<Vec<Column>> {
    let (config, base) = base_scene(s)?;
    let scenes: Vec<((String, Role), SceneFile)> = names
        .iter()
        .flat_map(|n| roles.iter().map(move |r| (n, *r)))
        .map(|(n, r)| ((n.to_string(), r), scene_for(&config, &base, n, r)))
        .collect();
    // The worker's catalogue: the materials measured and those the scene keeps.
    let mut used: Vec<&str> = names.to_vec();
    used.push(base.backdrop.material.name.as_str());
    used.extend(base.objects.iter().map(|o| o.material.name.as_str()));
    used.sort_unstable();
    used.dedup();
    let work = clevrtex_render::tmp::scratch_dir()?;
    let mut columns = Vec::new();
    for blender in blenders {
        let opts = RenderOptions {
            blender: blender.clone(),
            ..opts.clone()
        };
        let (mut session, _checked) = session(cat, &used, &opts)?;
        let version = session.ready()?.blender_version;
        let mut figures = Vec::new();
        for ((name, role), scene) in &scenes {
            let dir = work.path().join(format!("{name}-{}", role.name()));
            std::fs::create_dir_all(&dir)
                .with_context(|| format!("cannot create `{}`", dir.display()))?;
            let label = format!("{name} as {}", role.name());
            let started = std::time::Instant::now();
            let exr = render_scene(&mut session, &opts, &label, scene, &dir)?;
            let f = Channels::read(&exr)
                .map_err(anyhow::Error::from)
                .and_then(|ch| measure(&ch, *role))
                .with_context(|| format!("Blender {version}, material `{label}`"))?;
            progress(format!(
                "{version}: {label}: luminance {:.4}, depth {:.3} m, albedo {:.4} ({} px, {:.1} s)",
                f.luminance,
                f.depth,
                f.albedo,
                f.pixels,
                started.elapsed().as_secs_f64()
            ));
            figures.push(((name.clone(), *role), f));
            let _ = std::fs::remove_dir_all(&dir);
        }
        session.close();
        columns.push(Column {
            blender: blender.clone(),
            version,
            figures,
        });
    }
    Ok(columns)
}

/// Relative difference of `x` from `reference`.
fn ratio(x: f64, reference: f64) -> f64 {
    x / reference - 1.0
}

/// The Markdown table of `columns` (the first is the reference: each other Blender's figures
/// with their difference from it, `**past**` past a bound), and how many (material, role)
/// rows are past a bound.
pub fn table(columns: &[Column]) -> (String, usize) {
    let mut out = String::new();
    let Some(first) = columns.first() else {
        return (out, 0);
    };
    let _ = write!(
        out,
        "| material | as | {} luminance, depth m, albedo |",
        first.version
    );
    for c in &columns[1..] {
        let _ = write!(
            out,
            " {} luminance, depth m, albedo (/ {}) |",
            c.version, first.version
        );
    }
    out.push('\n');
    out.push_str(&"|---".repeat(columns.len() + 2));
    out.push_str("|\n");
    let mut past = 0;
    for ((name, role), reference) in &first.figures {
        let _ = write!(
            out,
            "| `{name}` | {} | {:.4}, {:.3}, {:.4} |",
            role.name(),
            reference.luminance,
            reference.depth,
            reference.albedo
        );
        let mut bad = false;
        for c in &columns[1..] {
            let Some((_, f)) = c.figures.iter().find(|(k, _)| k.0 == *name && k.1 == *role) else {
                out.push_str(" - |");
                continue;
            };
            let (dl, dd) = (
                ratio(f.luminance, reference.luminance),
                ratio(f.depth, reference.depth),
            );
            let over = !(dl.abs() <= LUMINANCE_BOUND && dd.abs() <= DEPTH_BOUND);
            bad |= over;
            let _ = write!(
                out,
                " {:.4} ({:+.1}%), {:.3} ({:+.3}%), {:.4} ({:+.1}%){} |",
                f.luminance,
                100.0 * dl,
                f.depth,
                100.0 * dd,
                f.albedo,
                100.0 * ratio(f.albedo, reference.albedo),
                if over { " **past**" } else { "" }
            );
        }
        past += usize::from(bad);
        out.push('\n');
    }
    (out, past)
}

/// The line that says what was rendered, with what.
pub fn header(names: usize, roles: &[Role], s: Settings, columns: &[Column]) -> String {
    let displacement = Config::builtin(VARIANT)
        .ok()
        .and_then(|c| c.background.displacement)
        .map_or("none".to_string(), |d| d.to_string());
    format!(
        "materials parity: {names} material(s) as {}, {}x{} px, {} samples, backdrop displacement {displacement} (scene {VARIANT}, seed {SEED}, index {INDEX}); Blenders: {}",
        roles.iter().map(|r| r.name()).collect::<Vec<_>>().join(" and "),
        s.width,
        (s.width * 3 / 4).max(1),
        s.samples,
        columns
            .iter()
            .enumerate()
            .map(|(i, c)| format!(
                "{} ({}{})",
                c.version,
                c.blender.display(),
                if i == 0 { ", the reference" } else { "" }
            ))
            .collect::<Vec<_>>()
            .join(", ")
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    fn column(version: &str, lum: f64, depth: f64) -> Column {
        let f = Figures {
            luminance: lum,
            depth,
            albedo: lum / 2.0,
            pixels: 10,
        };
        Column {
            blender: PathBuf::from("b"),
            version: version.to_string(),
            figures: vec![(("bricks".to_string(), Role::Backdrop), f)],
        }
    }

    #[test]
    fn the_table_marks_a_material_past_either_bound() {
        let within = [column("3.4", 0.2, 10.0), column("4.5", 0.205, 10.05)];
        let (t, past) = table(&within);
        assert_eq!(past, 0, "{t}");
        assert!(
            t.contains("0.2050 (+2.5%), 10.050 (+0.500%), 0.1025 (+2.5%) |"),
            "{t}"
        );
        let dark = [column("3.4", 0.2, 10.0), column("4.5", 0.193, 10.0)];
        let (t, past) = table(&dark);
        assert_eq!(past, 1);
        assert!(t.contains("(-3.5%)") && t.contains("**past**"), "{t}");
        let deep = [column("3.4", 0.2, 10.0), column("4.5", 0.2, 10.2)];
        assert_eq!(table(&deep).1, 1);
        let nan = [column("3.4", 0.2, 10.0), column("4.5", f64::NAN, 10.0)];
        assert_eq!(table(&nan).1, 1, "a NaN is past the bound");
    }

    #[test]
    fn the_scenes_put_the_material_where_the_role_says() {
        let (config, base) = base_scene(Settings {
            width: 64,
            samples: 8,
        })
        .unwrap();
        assert_eq!((base.render.width, base.render.height), (64, 48));
        assert!(base.backdrop.material.displacement.is_some());
        assert!(!base.objects.is_empty());
        let b = scene_for(&config, &base, "bricks", Role::Backdrop);
        assert_eq!(b.backdrop.material.name, "bricks");
        assert!(b.objects.is_empty());
        let o = scene_for(&config, &base, "bricks", Role::Object);
        assert_eq!(o.backdrop.material, base.backdrop.material);
        assert!(o.objects.iter().all(|o| o.material.name == "bricks"));
        assert_eq!(o.objects.len(), base.objects.len());
    }
}
