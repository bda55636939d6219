//! `clevrtex materials`: list the catalogue, print the resolved recipes, render a contact
//! sheet, check that every material builds, and measure distinctness and cost.

use std::io::Write;
use std::path::{Path, PathBuf};

use anyhow::{bail, Context};
use clevrtex_materials::tool::{self, Mode, ToolRun};
use clevrtex_materials::{Catalogue, Set};

use crate::exit::{CmdResult, OK};

#[path = "materials/sheet.rs"]
mod sheet;
#[path = "materials/stats.rs"]
mod stats;

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
}

#[derive(Debug, clap::Args)]
struct StatsArgs {
    #[command(flatten)]
    batch: BatchArgs,
    /// Tile size in pixels.
    #[arg(long, default_value_t = 128)]
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
    /// Image size in pixels.
    #[arg(long, default_value_t = 160)]
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
}

#[derive(Debug, clap::Args)]
struct SheetArgs {
    #[command(flatten)]
    batch: BatchArgs,
    /// Output PNG.
    #[arg(long)]
    out: PathBuf,
    /// Cell width in pixels (height is 3/4 of it).
    #[arg(long, default_value_t = 240)]
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

fn blender(a: &BatchArgs) -> anyhow::Result<PathBuf> {
    a.blender.clone().or_else(tool::find_blender).ok_or_else(|| {
        anyhow::anyhow!(
            "blender not found\nhint: install it (`apt-get install -y blender`) or pass `--blender PATH`"
        )
    })
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

/// Hash of the bridge scripts: a change to any of them invalidates every cached cell.
fn scripts_hash() -> u64 {
    let parts: Vec<&[u8]> = tool::SCRIPTS
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
        let run = ToolRun {
            blender: blender(&a.batch)?,
            mode: Mode::Sheet,
            size: a.size,
            samples: a.samples,
            threads: a.batch.threads,
            out_dir: tmp.clone(),
            displacement: 0.0,
            random: 0.37,
        };
        let replies = run.run(cat, &missing)?;
        let mut failed = Vec::new();
        for r in &replies {
            if r.value["ok"].as_bool() == Some(true) {
                let from = tmp.join(format!("{}.png", r.name));
                std::fs::rename(&from, cache.join(key(&r.name)))
                    .with_context(|| format!("cannot move `{}` into the cache", from.display()))?;
            } else {
                failed.push(format!("{}: {}", r.name, r.value["error"]));
            }
        }
        let _ = std::fs::remove_dir_all(&tmp);
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
    let run = ToolRun {
        blender: blender(&a)?,
        mode: Mode::Check,
        size: 64,
        samples: 2,
        threads: a.threads,
        out_dir: dir.clone(),
        displacement: 0.0,
        random: 0.37,
    };
    let replies = run.run(cat, &names)?;
    let _ = std::fs::remove_dir_all(&dir);
    let mut failed = 0;
    let mut out = std::io::stdout().lock();
    for r in &replies {
        let pink = r.value["pink"].as_f64().unwrap_or(0.0);
        let ok = r.value["ok"].as_bool() == Some(true) && pink == 0.0;
        if ok {
            let _ = writeln!(out, "ok     {}", r.name);
        } else {
            failed += 1;
            let why = r.value["error"]
                .as_str()
                .unwrap_or("pink (missing texture) pixels");
            let _ = writeln!(out, "FAILED {}: {why}", r.name);
            if let Some(tb) = r.value["traceback"].as_str() {
                let _ = writeln!(out, "{tb}");
            }
        }
    }
    if failed > 0 {
        bail!(
            "{failed} of {} material(s) failed to build or render\nhint: the traceback above names the block and parameter",
            replies.len()
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
    for (i, random) in [0.37, 0.81].into_iter().enumerate() {
        let run = ToolRun {
            blender: blender(&a.batch)?,
            mode: Mode::Tile,
            size: a.size,
            samples: a.samples,
            threads: a.batch.threads,
            out_dir: dir.join(format!("r{i}")),
            displacement: 0.0,
            random,
        };
        let replies = run.run(cat, &names)?;
        let mut f = Vec::new();
        for r in &replies {
            let Some(file) = r.value["file"].as_str() else {
                bail!(
                    "material `{}` failed: {}\nhint: run `clevrtex materials check --names {}`",
                    r.name,
                    r.value["error"],
                    r.name
                );
            };
            f.push(features(Path::new(file)).with_context(|| format!("cannot read `{file}`"))?);
        }
        feats.push(f);
    }
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
    let run = ToolRun {
        blender: blender(&a.batch)?,
        mode: Mode::Cost,
        size: a.size,
        samples: a.samples,
        threads: a.batch.threads,
        out_dir: dir.clone(),
        displacement: 0.0,
        random: 0.37,
    };
    let replies = run.run(cat, &names)?;
    let _ = std::fs::remove_dir_all(&dir);
    let time = |r: &tool::Reply| r.value["render_s"].as_f64().unwrap_or(f64::NAN);
    let plain = replies
        .iter()
        .find(|r| r.name == "plain")
        .map(time)
        .unwrap_or(f64::NAN);
    let mut rel: Vec<f64> = replies.iter().map(|r| time(r) / plain).collect();
    let mut out = std::io::stdout().lock();
    let _ = writeln!(out, "{:<24} {:>8} {:>8}", "material", "seconds", "x plain");
    for (r, x) in replies.iter().zip(&rel) {
        let _ = writeln!(out, "{:<24} {:>8.2} {:>8.2}", r.name, time(r), x);
    }
    let shown = rel.clone();
    rel.sort_by(f64::total_cmp);
    let median = rel[rel.len() / 2];
    let outliers: Vec<String> = replies
        .iter()
        .zip(&shown)
        .filter(|(_, x)| **x > 3.0 * median)
        .map(|(r, x)| format!("{} ({x:.2}x plain)", r.name))
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
