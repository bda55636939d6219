//! The Blender batches of `clevrtex materials check|stats|cost`: the renders each makes with
//! one worker (`clevrtex_render::material_renders`: user materials checked first, Ctrl-C
//! stopping Blender) and what comes back of them; the command prints.

use std::path::Path;

use anyhow::{bail, Context};
use clevrtex_materials::Catalogue;
use clevrtex_render::material_renders::{
    render_all, render_all_in_temp, session, Outcome, RenderOptions,
};
use clevrtex_render::{MaterialMode, MaterialSettings, RenderError};

use super::stats::{self, Features};

/// A material render of `mode` at `size` pixels wide with `samples`, no displacement.
pub(crate) fn settings(
    mode: MaterialMode,
    size: u32,
    samples: u32,
    random: f64,
) -> MaterialSettings {
    MaterialSettings {
        mode,
        size,
        samples,
        displacement: 0.0,
        random,
    }
}

/// `materials check`: each of `names` built and rendered small (64 px, 2 samples) in the
/// temporary folder `dir` (removed afterwards); how each came out, in order.
pub fn check(
    cat: &Catalogue,
    names: &[&str],
    opts: &RenderOptions,
    dir: &Path,
) -> Result<Vec<Outcome>, RenderError> {
    let settings = settings(MaterialMode::Check, 64, 2, 0.37);
    let (mut session, _checked) = session(cat, names, opts)?;
    let outcomes = render_all_in_temp(&mut session, opts, &settings, names, dir)?;
    session.close();
    Ok(outcomes)
}

/// `materials stats` as a whole: the materials `super::select` picks of `set` or `names`
/// (`rubber` and `metal` left out), their tiles rendered into `out_dir` (default: a temporary
/// folder, removed afterwards) with the options `opts` gives, and their distinctness.
pub fn distinctness<'a>(
    cat: &'a Catalogue,
    (set, names): (&str, &'a [String]),
    opts: &dyn Fn() -> anyhow::Result<RenderOptions>,
    size_samples: (u32, u32),
    out_dir: Option<&Path>,
) -> anyhow::Result<(Vec<&'a str>, stats::Distinctness)> {
    let mut chosen = super::select(cat, set, names)?;
    chosen.retain(|n| !matches!(*n, "rubber" | "metal"));
    if chosen.is_empty() {
        let what = if names.is_empty() {
            format!("set `{set}`")
        } else {
            "`--names`".to_string()
        };
        bail!(
            "no materials to compare in {what} (`rubber` and `metal` are left out)\nhint: pick another `--set` or `--names`"
        );
    }
    let dir = out_dir.map(Path::to_path_buf).unwrap_or_else(|| {
        std::env::temp_dir().join(format!("clevrtex-stats-{}", std::process::id()))
    });
    let feats = tile_features(cat, &chosen, &opts()?, size_samples, &dir)?;
    // The same material with another `random` is the yardstick (`stats::distinctness`).
    let d = stats::distinctness(&feats[0], &feats[1]);
    if out_dir.is_none() {
        let _ = std::fs::remove_dir_all(&dir);
    }
    Ok((chosen, d))
}

/// `materials stats`: a tile of each of `names` at `size` px and `samples`, rendered twice
/// (`random` 0.37 and 0.81, into `dir/r0` and `dir/r1`), and the features of each tile: the
/// two lists [`stats::distinctness`] compares. A material that fails to build is an error
/// naming it; a render error comes back as a [`RenderError`] inside the error.
pub fn tile_features(
    cat: &Catalogue,
    names: &[&str],
    opts: &RenderOptions,
    (size, samples): (u32, u32),
    dir: &Path,
) -> anyhow::Result<Vec<Vec<Features>>> {
    let mut feats = Vec::new();
    let (mut session, _checked) = session(cat, names, opts)?;
    for (i, random) in [0.37, 0.81].into_iter().enumerate() {
        let settings = settings(MaterialMode::Tile, size, samples, random);
        let out_dir = dir.join(format!("r{i}"));
        let outcomes = render_all(&mut session, opts, &settings, names, &out_dir)?;
        let mut f = Vec::new();
        for (name, outcome) in names.iter().zip(outcomes) {
            let file = match outcome {
                Outcome::Done(reply) => reply.file,
                Outcome::Failed { message, .. } => bail!(
                    "material `{name}` failed: {message}\nhint: run `clevrtex materials check --names {name}`"
                ),
            };
            f.push(
                stats::features(&file)
                    .with_context(|| format!("cannot read `{}`", file.display()))?,
            );
        }
        feats.push(f);
    }
    session.close();
    Ok(feats)
}

/// `materials cost` as a whole: the materials `super::select` picks of `set` or `names`,
/// `plain` first when not among them, and each one's render seconds ([`render_seconds`],
/// with the options `opts` gives).
pub fn costs<'a>(
    cat: &'a Catalogue,
    (set, names): (&str, &'a [String]),
    opts: &dyn Fn() -> anyhow::Result<RenderOptions>,
    size_samples: (u32, u32),
) -> anyhow::Result<(Vec<&'a str>, Vec<f64>)> {
    let mut chosen = super::select(cat, set, names)?;
    if !chosen.contains(&"plain") {
        chosen.insert(0, "plain");
    }
    let dir = std::env::temp_dir().join(format!("clevrtex-cost-{}", std::process::id()));
    let times = render_seconds(cat, &chosen, &opts()?, size_samples, &dir)?;
    Ok((chosen, times))
}

/// `materials cost`: the render seconds of each of `names` at `size` px and `samples`, in the
/// temporary folder `dir` (removed afterwards); a material that failed to build has no time
/// (NaN), so it shows as such in the table.
pub fn render_seconds(
    cat: &Catalogue,
    names: &[&str],
    opts: &RenderOptions,
    (size, samples): (u32, u32),
    dir: &Path,
) -> Result<Vec<f64>, RenderError> {
    let settings = settings(MaterialMode::Cost, size, samples, 0.37);
    let (mut session, _checked) = session(cat, names, opts)?;
    let outcomes = render_all_in_temp(&mut session, opts, &settings, names, dir)?;
    session.close();
    Ok(outcomes
        .iter()
        .map(|o| match o {
            Outcome::Done(reply) => reply.timings.render_s,
            Outcome::Failed { .. } => f64::NAN,
        })
        .collect())
}
