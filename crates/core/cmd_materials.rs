//! `clevrtex materials`: list the catalogue, print the resolved recipes, render a contact
//! sheet, check that every material builds, and measure distinctness and cost.
//!
//! The renders are `material` requests of the bridge protocol (`docs/bridge-protocol.md`),
//! one per material, sent to one Blender worker with `generate`'s failure policy: a time
//! limit per request, a crashed or hung worker restarted and the request retried
//! (`--retries`), Ctrl-C stopping Blender at once.

use std::io::Write;
use std::path::{Path, PathBuf};
use std::time::Duration;

use anyhow::{bail, Context};
use clevrtex_materials::{Catalogue, Set};
use clevrtex_render::{MaterialMode, MaterialReply, MaterialSettings, RenderError};

use crate::blender_session::{command_error, BlenderSession, Settings};
use crate::exit::{CmdResult, OK};
use crate::interrupt::{self, OnInterrupt};

#[path = "materials/figures.rs"]
mod figures;
#[path = "materials/sheet.rs"]
mod sheet;
#[path = "materials/stats.rs"]
pub(crate) mod stats;

/// Arguments of `clevrtex materials`.
#[derive(Debug, clap::Args)]
pub struct Args {
    #[command(subcommand)]
    command: Sub,
    /// Extra materials: `.json` files in our format and `.blend` files with a ClevrTex-style
    /// node group (inputs Color/Random/Displacement/Scale, outputs Shader and Displacement).
    #[arg(long, global = true, value_name = "DIR")]
    materials: Option<PathBuf>,
}

#[derive(Debug, clap::Subcommand)]
enum Sub {
    /// List every material: name, set, whether it displaces, description.
    List,
    /// Print the resolved catalogue (`materials.json`, as the Blender bridge receives it).
    Json,
    /// Render a labelled contact sheet: each material on a sphere and a cube.
    Sheet(SheetArgs),
    /// Build and render every material small; fail on Blender errors or pink pixels.
    Check(BatchArgs),
    /// Distinctness: texture statistics of flat-lit tiles, nearest neighbours, near-copies.
    Stats(StatsArgs),
    /// Render time of each material on a sphere, relative to `plain`.
    Cost(CostArgs),
    /// Measure a rendered dataset (no Blender): albedo spread, interior/boundary gradient
    /// ratio and scale ratio, per variant and per material (docs/materials.md).
    Measure(MeasureArgs),
}

#[derive(Debug, clap::Args)]
struct MeasureArgs {
    /// The dataset: the `--out` folder of `clevrtex generate` or one `clevrtex_<variant>`
    /// folder (needs the mask; the RGB image for the gradient ratio, the albedo pass for the
    /// spread and the scale ratio).
    dataset: PathBuf,
    /// Print JSON (every image's figures and the summaries) instead of tables.
    #[arg(long)]
    json: bool,
}

#[derive(Debug, clap::Args)]
struct StatsArgs {
    #[command(flatten)]
    batch: BatchArgs,
    /// Tile size in pixels (16 to 4096).
    #[arg(long, default_value_t = 128, value_parser = clap::value_parser!(u32).range(16..=4096))]
    size: u32,
    /// Samples per pixel.
    #[arg(long, default_value_t = 16)]
    samples: u32,
    /// Keep the tiles here (default: a temporary directory).
    #[arg(long)]
    out_dir: Option<PathBuf>,
}

#[derive(Debug, clap::Args)]
struct CostArgs {
    #[command(flatten)]
    batch: BatchArgs,
    /// Image size in pixels (16 to 4096).
    #[arg(long, default_value_t = 160, value_parser = clap::value_parser!(u32).range(16..=4096))]
    size: u32,
    /// Samples per pixel.
    #[arg(long, default_value_t = 64)]
    samples: u32,
}

#[derive(Debug, clap::Args)]
struct BatchArgs {
    /// Which materials: main, ood, basic, background, user or all.
    #[arg(long, default_value = "all")]
    set: String,
    /// Only these materials (comma-separated), instead of `--set`.
    #[arg(long, value_delimiter = ',')]
    names: Vec<String>,
    /// Blender executable (default: `CLEVRTEX_BLENDER`, else `blender` on `PATH`).
    #[arg(long, env = "CLEVRTEX_BLENDER")]
    blender: Option<PathBuf>,
    /// Cycles threads (0: automatic).
    #[arg(long, default_value_t = 0)]
    threads: u32,
    /// Time limit per material render, seconds; a worker over it is killed and the render
    /// retried. Default: 600 + 8 per sample at 320x240, and a worker silent for 300 s counts
    /// as hung.
    #[arg(long, value_name = "SECONDS")]
    timeout: Option<f64>,
    /// Restarts of a crashed or hung Blender worker per material before the command stops.
    #[arg(long, default_value_t = 2, value_name = "N")]
    retries: u32,
    /// Time limit for a Blender worker to start (load the bridge and answer `ready`), seconds.
    #[arg(long, default_value_t = clevrtex_render::STARTUP_TIMEOUT.as_secs_f64(), value_name = "SECONDS")]
    startup_timeout: f64,
}

#[derive(Debug, clap::Args)]
struct SheetArgs {
    #[command(flatten)]
    batch: BatchArgs,
    /// Output PNG.
    #[arg(long)]
    out: PathBuf,
    /// Cell width in pixels, 16 to 4096 (height is 3/4 of it).
    #[arg(long, default_value_t = 240, value_parser = clap::value_parser!(u32).range(16..=4096))]
    size: u32,
    /// Samples per pixel.
    #[arg(long, default_value_t = 24)]
    samples: u32,
    /// Cells per row.
    #[arg(long, default_value_t = 8)]
    cols: usize,
    /// Cell cache (default: `$XDG_CACHE_HOME/clevrtex/sheet` or `~/.cache/clevrtex/sheet`).
    /// Cells are keyed by the material's content hash, the bridge scripts and the settings.
    #[arg(long)]
    cache: Option<PathBuf>,
}

/// Run `clevrtex materials`.
pub fn run(args: Args) -> CmdResult {
    let cat = load(args.materials.as_deref())?;
    match args.command {
        Sub::List => {
            let mut out = std::io::stdout().lock();
            let _ = writeln!(
                out,
                "{:<26} {:<10} {:<9} description",
                "name", "set", "displaces"
            );
            for m in cat.iter() {
                let d = if m.displaces { "yes" } else { "no" };
                let line = format!("{:<26} {:<10} {:<9} {}", m.name, m.set, d, m.description);
                if writeln!(out, "{line}").is_err() {
                    break;
                }
            }
            Ok(OK)
        }
        Sub::Json => {
            let _ = writeln!(std::io::stdout().lock(), "{}", cat.resolved_json());
            Ok(OK)
        }
        Sub::Sheet(a) => sheet(&cat, a),
        Sub::Check(a) => check(&cat, a),
        Sub::Stats(a) => stats(&cat, a),
        Sub::Cost(a) => cost(&cat, a),
        Sub::Measure(a) => measure(a),
    }
}

/// The built-in catalogue plus the user directory, if any.
pub fn load(dir: Option<&Path>) -> anyhow::Result<Catalogue> {
    let mut cat = Catalogue::builtin().context("the built-in material catalogue is invalid")?;
    if let Some(dir) = dir {
        cat.add_user_dir(dir)?;
    }
    Ok(cat)
}

fn select<'a>(cat: &'a Catalogue, a: &'a BatchArgs) -> anyhow::Result<Vec<&'a str>> {
    if !a.names.is_empty() {
        for n in &a.names {
            cat.require(n)?;
        }
        return Ok(a.names.iter().map(String::as_str).collect());
    }
    if a.set == "all" {
        return Ok(cat.iter().map(|m| m.name.as_str()).collect());
    }
    let Some(set) = Set::from_name(&a.set) else {
        bail!(
            "unknown material set `{}`\nhint: use main, ood, basic, background, user or all",
            a.set
        );
    };
    Ok(cat.names(set))
}

/// How one material's render came out.
enum Outcome {
    /// Rendered.
    Done(MaterialReply),
    /// The bridge could not build or render it (the worker survived).
    Failed {
        /// The bridge's message.
        message: String,
        /// The Python traceback (may be empty).
        traceback: String,
    },
}

/// One Blender worker for the materials `names` of `cat`, started on the first render, with
/// a Ctrl-C handler that stops it.
fn session(cat: &Catalogue, names: &[&str], a: &BatchArgs) -> anyhow::Result<BlenderSession> {
    if let Some(t) = a.timeout {
        if !(t > 0.0 && t.is_finite()) {
            bail!(
                "`--timeout {t}` must be a positive number of seconds\nhint: e.g. `--timeout 600`"
            );
        }
    }
    let blender = clevrtex_render::blender::locate(a.blender.as_deref())?;
    let interrupt = interrupt::flag(OnInterrupt::Stop {
        message: "stopping Blender",
    });
    BlenderSession::new(Settings {
        blender,
        materials_json: cat.resolved_json_for(names.iter().copied()),
        threads: a.threads,
        retries: a.retries,
        // With an explicit `--timeout` that limit is the only one, as in `generate`.
        idle_timeout: a
            .timeout
            .is_none()
            .then_some(clevrtex_render::pool::IDLE_TIMEOUT),
        interrupt,
        startup_timeout: crate::run_args::seconds("--startup-timeout", a.startup_timeout)?,
    })
}

/// The time limit of one render: `--timeout`, else 600 s + 8 s per sample at 320x240 (the
/// rule `generate` uses for scenes).
fn timeout(a: &BatchArgs, s: &MaterialSettings) -> Duration {
    let pixels = f64::from(s.size) * f64::from(s.size) / (320.0 * 240.0);
    let auto = 600.0 + 8.0 * f64::from(s.samples) * pixels.max(0.05);
    Duration::from_secs_f64(a.timeout.unwrap_or(auto))
}

/// Render each of `names` with `settings` into `out_dir/<name>.png`, in order. A material the
/// bridge cannot build is an [`Outcome::Failed`] and the batch goes on; a worker that keeps
/// failing (after `--retries` restarts) or an interrupt ends it with an error.
fn render_all(
    session: &mut BlenderSession,
    a: &BatchArgs,
    settings: &MaterialSettings,
    names: &[&str],
    out_dir: &Path,
) -> anyhow::Result<Vec<Outcome>> {
    std::fs::create_dir_all(out_dir)
        .with_context(|| format!("cannot create `{}`", out_dir.display()))?;
    let limit = timeout(a, settings);
    names
        .iter()
        .map(
            |name| match session.request(|w| w.material(settings, name, out_dir, limit)) {
                Ok(reply) => Ok(Outcome::Done(reply)),
                Err(RenderError::Bridge {
                    message, traceback, ..
                }) => Ok(Outcome::Failed { message, traceback }),
                Err(e) => Err(command_error(e)),
            },
        )
        .collect()
}

/// [`render_all`] into `dir`, which is removed afterwards whatever happened.
fn render_all_in_temp(
    session: &mut BlenderSession,
    a: &BatchArgs,
    settings: &MaterialSettings,
    names: &[&str],
    dir: &Path,
) -> anyhow::Result<Vec<Outcome>> {
    let result = render_all(session, a, settings, names, dir);
    let _ = std::fs::remove_dir_all(dir);
    result
}

fn cache_dir(explicit: Option<PathBuf>) -> PathBuf {
    if let Some(p) = explicit {
        return p;
    }
    let base = std::env::var_os("XDG_CACHE_HOME")
        .map(PathBuf::from)
        .or_else(|| std::env::var_os("HOME").map(|h| PathBuf::from(h).join(".cache")))
        .unwrap_or_else(std::env::temp_dir);
    base.join("clevrtex").join("sheet")
}

/// Hash of the embedded bridge scripts: a change to any of them invalidates every cached
/// cell.
fn scripts_hash() -> u64 {
    let parts: Vec<&[u8]> = clevrtex_render::bridge::files()
        .iter()
        .flat_map(|(name, text)| [name.as_bytes(), text.as_bytes()])
        .collect();
    clevrtex_materials::content_hash(&parts)
}

fn sheet(cat: &Catalogue, a: SheetArgs) -> CmdResult {
    let names = select(cat, &a.batch)?;
    if names.is_empty() {
        bail!(
            "no materials in set `{}`\nhint: pick another `--set`",
            a.batch.set
        );
    }
    let cache = cache_dir(a.cache.clone());
    let key = |name: &str| {
        let m = cat.get(name).expect("selected from the catalogue");
        format!(
            "{name}-{}-{:016x}-{}x{}.png",
            m.hash,
            scripts_hash(),
            a.size,
            a.samples
        )
    };
    let missing: Vec<&str> = names
        .iter()
        .copied()
        .filter(|n| !cache.join(key(n)).is_file())
        .collect();
    eprintln!(
        "sheet: {} materials, {} cached, {} to render",
        names.len(),
        names.len() - missing.len(),
        missing.len()
    );
    if !missing.is_empty() {
        let tmp = cache.join(format!("tmp-{}", std::process::id()));
        let settings = MaterialSettings {
            mode: MaterialMode::Sheet,
            size: a.size,
            samples: a.samples,
            displacement: 0.0,
            random: 0.37,
        };
        let mut session = session(cat, &missing, &a.batch)?;
        let result =
            render_all(&mut session, &a.batch, &settings, &missing, &tmp).and_then(|outcomes| {
                session.close();
                let mut failed = Vec::new();
                for (name, outcome) in missing.iter().zip(outcomes) {
                    match outcome {
                        Outcome::Done(reply) => {
                            std::fs::rename(&reply.file, cache.join(key(name))).with_context(
                                || format!("cannot move `{}` into the cache", reply.file.display()),
                            )?;
                        }
                        Outcome::Failed { message, .. } => {
                            failed.push(format!("{name}: {message}"))
                        }
                    }
                }
                Ok(failed)
            });
        let _ = std::fs::remove_dir_all(&tmp);
        let failed = result?;
        if !failed.is_empty() {
            bail!(
                "{} material(s) failed to build:\n{}\nhint: run `clevrtex materials check --names <name>` for the traceback",
                failed.len(),
                failed.join("\n")
            );
        }
    }
    let cells: Vec<PathBuf> = names.iter().map(|n| cache.join(key(n))).collect();
    let img = sheet::stitch(&cells, a.cols).context("cannot assemble the sheet")?;
    img.save(&a.out)
        .with_context(|| format!("cannot write `{}`", a.out.display()))?;
    eprintln!("wrote {}", a.out.display());
    Ok(OK)
}

fn check(cat: &Catalogue, a: BatchArgs) -> CmdResult {
    let names = select(cat, &a)?;
    let dir = std::env::temp_dir().join(format!("clevrtex-check-{}", std::process::id()));
    let settings = MaterialSettings {
        mode: MaterialMode::Check,
        size: 64,
        samples: 2,
        displacement: 0.0,
        random: 0.37,
    };
    let mut session = session(cat, &names, &a)?;
    let outcomes = render_all_in_temp(&mut session, &a, &settings, &names, &dir)?;
    session.close();
    let mut failed = 0;
    let mut out = std::io::stdout().lock();
    for (name, outcome) in names.iter().zip(&outcomes) {
        match outcome {
            Outcome::Done(reply) if reply.measures.get("pink").copied().unwrap_or(0.0) == 0.0 => {
                let _ = writeln!(out, "ok     {name}");
            }
            Outcome::Done(_) => {
                failed += 1;
                let _ = writeln!(out, "FAILED {name}: pink (missing texture) pixels");
            }
            Outcome::Failed { message, traceback } => {
                failed += 1;
                let _ = writeln!(out, "FAILED {name}: {message}");
                if !traceback.is_empty() {
                    let _ = writeln!(out, "{traceback}");
                }
            }
        }
    }
    if failed > 0 {
        bail!(
            "{failed} of {} material(s) failed to build or render\nhint: the traceback above names the block and parameter",
            outcomes.len()
        );
    }
    Ok(OK)
}

fn stats(cat: &Catalogue, a: StatsArgs) -> CmdResult {
    use stats::{distance, features};
    let mut names = select(cat, &a.batch)?;
    names.retain(|n| !matches!(*n, "rubber" | "metal"));
    let dir = a.out_dir.clone().unwrap_or_else(|| {
        std::env::temp_dir().join(format!("clevrtex-stats-{}", std::process::id()))
    });
    let mut feats = Vec::new();
    let mut session = session(cat, &names, &a.batch)?;
    for (i, random) in [0.37, 0.81].into_iter().enumerate() {
        let settings = MaterialSettings {
            mode: MaterialMode::Tile,
            size: a.size,
            samples: a.samples,
            displacement: 0.0,
            random,
        };
        let out_dir = dir.join(format!("r{i}"));
        let outcomes = render_all(&mut session, &a.batch, &settings, &names, &out_dir)?;
        let mut f = Vec::new();
        for (name, outcome) in names.iter().zip(outcomes) {
            let file = match outcome {
                Outcome::Done(reply) => reply.file,
                Outcome::Failed { message, .. } => bail!(
                    "material `{name}` failed: {message}\nhint: run `clevrtex materials check --names {name}`"
                ),
            };
            f.push(features(&file).with_context(|| format!("cannot read `{}`", file.display()))?);
        }
        feats.push(f);
    }
    session.close();
    // The same material with another `random` is the yardstick: two different materials
    // closer than the farthest pair of instances of one material could pass for one.
    let intra: Vec<f64> = (0..names.len())
        .map(|i| distance(&feats[0][i], &feats[1][i]))
        .collect();
    let mut sorted = intra.clone();
    sorted.sort_by(f64::total_cmp);
    let threshold = sorted[sorted.len() / 2];
    let mut out = std::io::stdout().lock();
    let _ = writeln!(
        out,
        "{:<24} {:<24} {:>8} {:>8}",
        "material", "nearest", "distance", "self"
    );
    let mut near = Vec::new();
    let mut min_inter = f64::INFINITY;
    for i in 0..names.len() {
        let (j, d) = (0..names.len())
            .filter(|&j| j != i)
            .map(|j| (j, distance(&feats[0][i], &feats[0][j])))
            .min_by(|x, y| x.1.total_cmp(&y.1))
            .unwrap_or((i, f64::NAN));
        min_inter = min_inter.min(d);
        let _ = writeln!(
            out,
            "{:<24} {:<24} {:>8.3} {:>8.3}",
            names[i], names[j], d, intra[i]
        );
        if d < threshold && i < j {
            near.push(format!("`{}` ~ `{}` ({d:.3})", names[i], names[j]));
        }
    }
    let _ = writeln!(
        out,
        "self-distance (same material, random 0.37 vs 0.81): median {threshold:.3}, max {:.3}; smallest distance between different materials {min_inter:.3}",
        sorted[sorted.len() - 1]
    );
    if a.out_dir.is_none() {
        let _ = std::fs::remove_dir_all(&dir);
    }
    if !near.is_empty() {
        bail!(
            "{} pair(s) of materials are closer than the median self-distance {threshold:.3}:\n{}\nhint: change the colours or the pattern scale of one of each pair",
            near.len(),
            near.join("\n")
        );
    }
    Ok(OK)
}

fn cost(cat: &Catalogue, a: CostArgs) -> CmdResult {
    let mut names = select(cat, &a.batch)?;
    if !names.contains(&"plain") {
        names.insert(0, "plain");
    }
    let dir = std::env::temp_dir().join(format!("clevrtex-cost-{}", std::process::id()));
    let settings = MaterialSettings {
        mode: MaterialMode::Cost,
        size: a.size,
        samples: a.samples,
        displacement: 0.0,
        random: 0.37,
    };
    let mut session = session(cat, &names, &a.batch)?;
    let outcomes = render_all_in_temp(&mut session, &a.batch, &settings, &names, &dir)?;
    session.close();
    // A material that failed to build has no time (NaN), so it shows as such in the table.
    let times: Vec<f64> = outcomes
        .iter()
        .map(|o| match o {
            Outcome::Done(reply) => reply.timings.render_s,
            Outcome::Failed { .. } => f64::NAN,
        })
        .collect();
    let plain = names
        .iter()
        .zip(&times)
        .find(|(n, _)| **n == "plain")
        .map_or(f64::NAN, |(_, t)| *t);
    let mut rel: Vec<f64> = times.iter().map(|t| t / plain).collect();
    let mut out = std::io::stdout().lock();
    let _ = writeln!(out, "{:<24} {:>8} {:>8}", "material", "seconds", "x plain");
    for ((name, t), x) in names.iter().zip(&times).zip(&rel) {
        let _ = writeln!(out, "{name:<24} {t:>8.2} {x:>8.2}");
    }
    let shown = rel.clone();
    rel.sort_by(f64::total_cmp);
    let median = rel[rel.len() / 2];
    let outliers: Vec<String> = names
        .iter()
        .zip(&shown)
        .filter(|(_, x)| **x > 3.0 * median)
        .map(|(name, x)| format!("{name} ({x:.2}x plain)"))
        .collect();
    let _ = writeln!(
        out,
        "median {median:.2}x plain, max {:.2}x plain; over 3x the median: {}",
        rel[rel.len() - 1],
        if outliers.is_empty() {
            "none".to_string()
        } else {
            outliers.join(", ")
        }
    );
    Ok(OK)
}

fn measure(a: MeasureArgs) -> CmdResult {
    use figures::median;
    let samples = figures::measure_dataset(&a.dataset)?;
    let (variants, materials) = figures::summarise(&samples);
    let med = |v: &[f64]| median(v).unwrap_or(f64::NAN);
    // A figure with nothing measured prints as `-`.
    let f = |v: f64, digits: usize| {
        if v.is_nan() {
            "-".to_string()
        } else {
            format!("{v:.digits$}")
        }
    };
    let mut out = std::io::stdout().lock();
    if a.json {
        let summary = |s: &figures::Summary| {
            serde_json::json!({
                "images": s.images,
                "object_spread": s.object_spread,
                "background_spread": s.background_spread,
                "median_object_spread": median(&s.object_spread),
                "median_background_spread": median(&s.background_spread),
                "gradient_ratio": s.gradient,
                "median_gradient_ratio": median(&s.gradient),
                "scale": s.scale,
                "median_scale": median(&s.scale),
            })
        };
        let images: Vec<serde_json::Value> = samples
            .iter()
            .map(|s| {
                let by_id = |m: &std::collections::BTreeMap<u32, f64>| {
                    m.iter()
                        .map(|(id, v)| (id.to_string(), serde_json::json!(v)))
                        .collect::<serde_json::Map<_, _>>()
                };
                serde_json::json!({
                    "variant": s.variant,
                    "stem": s.stem,
                    "materials": s.materials.iter().map(|(id, m)| (id.to_string(), serde_json::json!(m))).collect::<serde_json::Map<_, _>>(),
                    "albedo_spread": by_id(&s.spread),
                    "gradient_ratio": s.gradient.as_ref().and_then(|g| g.ratio),
                    "region_gradient_ratio": s.gradient.as_ref().map(|g| by_id(&g.regions)),
                    "scale_q": by_id(&s.scale.q),
                    "scale_ratio": s.scale.ratio,
                })
            })
            .collect();
        let doc = serde_json::json!({
            "variants": variants.iter().map(|(k, s)| (k.clone(), summary(s))).collect::<serde_json::Map<_, _>>(),
            "materials": materials.iter().map(|(k, s)| (k.clone(), summary(s))).collect::<serde_json::Map<_, _>>(),
            "images": images,
        });
        let _ = writeln!(out, "{doc:#}");
        return Ok(OK);
    }
    let _ = writeln!(
        out,
        "{:<10} {:>6} {:>13} {:>13} {:>22} {:>13}",
        "variant", "images", "spread obj", "spread bg", "gradient in/bnd", "scale bg/obj"
    );
    for (name, s) in &variants {
        let range = |v: &[f64]| {
            let lo = v.iter().copied().fold(f64::INFINITY, f64::min);
            let hi = v.iter().copied().fold(f64::NEG_INFINITY, f64::max);
            if v.is_empty() {
                "-".to_string()
            } else {
                format!("{:.2} ({lo:.2}-{hi:.2})", med(v))
            }
        };
        let _ = writeln!(
            out,
            "{:<10} {:>6} {:>13} {:>13} {:>22} {:>13}",
            name,
            s.images,
            f(med(&s.object_spread), 1),
            f(med(&s.background_spread), 1),
            range(&s.gradient),
            f(med(&s.scale), 2),
        );
    }
    let _ = writeln!(out);
    let _ = writeln!(
        out,
        "{:<26} {:>7} {:>10} {:>10} {:>9} {:>8}",
        "material", "regions", "spread obj", "spread bg", "gradient", "q"
    );
    let mut rows: Vec<(&String, &figures::Summary)> = materials.iter().collect();
    rows.sort_by(|a, b| {
        let key = |s: &figures::Summary| {
            let mut all = s.object_spread.clone();
            all.extend(&s.background_spread);
            med(&all)
        };
        key(a.1).total_cmp(&key(b.1)).then(a.0.cmp(b.0))
    });
    for (name, s) in rows {
        let regions = s.object_spread.len() + s.background_spread.len();
        let _ = writeln!(
            out,
            "{:<26} {:>7} {:>10} {:>10} {:>9} {:>8}",
            name,
            regions,
            f(med(&s.object_spread), 1),
            f(med(&s.background_spread), 1),
            f(med(&s.gradient), 2),
            f(med(&s.scale), 3),
        );
    }
    let _ = writeln!(
        out,
        "\nmedians; spread: CIELAB std of the albedo per region (photo textures: several times 3-5; goal >= 8);\ngradient: mean interior over mean boundary gradient of the 128x128 crop (photos ~0.37; goal >= 0.35);\nscale: q = D(1)/D(4) of the albedo's L, backdrop over objects (goal 0.9-1.1 on camo). docs/materials.md"
    );
    Ok(OK)
}
