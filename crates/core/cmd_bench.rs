//! `clevrtex bench render`: error against run time of Cycles settings.
//!
//! Renders a fixed set of scenes (several variants, fixed seeds) at a ladder of settings
//! ([`ladder`]), compares each render with a high-sample reference of the same scene (cached
//! under `OUT/references/<hash>/`, keyed by the reference scene file, the recipes of the
//! materials it uses and the Blender version), and writes a table (stdout), a CSV and a log-log plot of error against time.
//! See `docs/performance.md`, section `bench`.

use std::collections::BTreeMap;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use anyhow::{bail, Context};
use clevrtex_render::exr_io::Channels;
use clevrtex_render::Mode;
use clevrtex_scene::quality::{Quality, Sampling};
use clevrtex_scene::{Config, Pass, SampleRequest, SceneFile};

use crate::blender_session::{command_error, BlenderSession, Settings};
use crate::exit::{self, CmdResult};
use crate::interrupt::{self, OnInterrupt};

#[path = "bench/ladder.rs"]
mod ladder;
#[path = "bench/metrics.rs"]
mod metrics;
#[path = "bench/plot.rs"]
mod plot;

use ladder::Setting;
use metrics::Errors;

/// Arguments of `clevrtex bench`.
#[derive(Debug, clap::Args)]
pub struct Args {
    #[command(subcommand)]
    what: What,
}

#[derive(Debug, clap::Subcommand)]
enum What {
    /// Error against run time of render settings, against a cached high-sample reference.
    Render(RenderArgs),
}

/// Arguments of `clevrtex bench render`.
#[derive(Debug, clap::Args)]
pub struct RenderArgs {
    /// A few minutes instead of hours: 160x120, 2 scenes, fewer rungs, 1024-sample
    /// references. Numbers are for comparing settings, not for the docs' per-image costs.
    #[arg(long)]
    quick: bool,
    #[arg(long, value_name = "N", help = format!(
        "Number of scenes (default 8, 2 with `--quick`); scene i is image i of the variant `{}` (cycling), seed {SEED}",
        VARIANTS.join(", ")
    ))]
    scenes: Option<usize>,
    /// Output folder: CSV, plot, renders and the reference cache.
    #[arg(long, default_value = "bench-out", value_name = "DIR")]
    out: PathBuf,
    /// Image width (default 320, 160 with `--quick`).
    #[arg(long)]
    width: Option<u32>,
    /// Image height (default 240, 120 with `--quick`).
    #[arg(long)]
    height: Option<u32>,
    /// Fixed samples of the reference renders (default 4096, 1024 with `--quick`), with the
    /// original generator's bounces.
    #[arg(long, value_name = "N")]
    reference_samples: Option<u32>,
    /// Skip rungs with more samples than this (e.g. to try the command quickly).
    #[arg(long, value_name = "N")]
    max_samples: Option<u32>,
    /// Also the rungs of Cycles 4.x's levers (light tree off, path guiding, blue noise,
    /// OIDN-denoised RGB); needs a Blender 4.x or 5.x (e.g. `--blender .venv-bpy/bin/python`).
    #[arg(long)]
    levers: bool,
    /// Only rungs whose label contains one of these (comma-separated), e.g. `original,preset`.
    #[arg(long, value_delimiter = ',', value_name = "LIST")]
    only: Option<Vec<String>>,
    /// Render nothing: redraw the table, summary and plot from `OUT/bench-render.csv`.
    #[arg(long)]
    plot_only: bool,
    /// Cycles threads (default: Blender's choice, all cores).
    #[arg(long, default_value_t = 0, value_name = "T")]
    threads: u32,
    /// Restarts of a crashed or hung Blender worker per render before the bench stops.
    #[arg(long, default_value_t = 2, value_name = "N")]
    retries: u32,
    /// Time limit for a Blender worker to start (load the bridge and answer `ready`), seconds.
    #[arg(long, default_value_t = clevrtex_render::STARTUP_TIMEOUT.as_secs_f64(), value_name = "SECONDS")]
    startup_timeout: f64,
    /// Blender: an executable, or a Python that imports `bpy` (default: `blender` on PATH, else
    /// `./.venv-bpy/bin/python`).
    #[arg(long, env = "CLEVRTEX_BLENDER", value_name = "PATH")]
    blender: Option<PathBuf>,
}

/// Run `clevrtex bench`.
pub fn run(args: Args) -> CmdResult {
    match args.what {
        What::Render(a) => run_render(a),
    }
}

/// Variants of the bench scenes, cycled.
const VARIANTS: [&str; 8] = [
    "full", "camo", "pbg", "vbg", "grassbg", "outd", "clevr", "full",
];
/// Seed of the bench scenes: fixed, so every machine benchmarks the same images.
const SEED: u64 = 2024;
/// Cycles seed of the references (the rungs use the default, 0).
const REFERENCE_SEED: u32 = 1;

struct BenchScene {
    label: String,
    scene: SceneFile,
}

/// One measured (setting, scene) pair.
#[derive(Debug)]
struct Row {
    scene: String,
    variant: String,
    width: u32,
    height: u32,
    setting: Setting,
    wall_s: f64,
    cycles_s: f64,
    errors: Errors,
}

/// The reference of one scene, decoded.
struct Reference {
    rgb: Vec<f32>,
    srgb: Vec<u8>,
    mask: Vec<f32>,
    depth: Vec<f32>,
    mean: f64,
}

fn bench_scenes(n: usize, width: u32, height: u32) -> anyhow::Result<Vec<BenchScene>> {
    (0..n)
        .map(|i| {
            let variant = VARIANTS[i % VARIANTS.len()];
            let mut config = Config::builtin(variant)?;
            config.base.render.width = width;
            config.base.render.height = height;
            config.base.passes = vec![Pass::Rgb, Pass::Mask, Pass::Depth];
            let req = SampleRequest {
                seed: SEED,
                index: i as u64,
                attempt: 0,
                total: 1000.max(n as u64),
            };
            let scene = clevrtex_scene::sample(&config, &req)?;
            Ok(BenchScene {
                label: format!("{variant}#{i}"),
                scene,
            })
        })
        .collect()
}

fn with_sampling(scene: &SceneFile, s: &Sampling) -> SceneFile {
    let mut scene = scene.clone();
    s.apply(&mut scene.render);
    scene
}

/// Per-request time limit: generous (the machine may be shared), scaled with the work.
fn timeout_for(scene: &SceneFile) -> Duration {
    let r = &scene.render;
    let work = f64::from(r.samples) * f64::from(r.width) * f64::from(r.height);
    Duration::from_secs_f64(300.0 + work * 4e-5)
}

struct Bench {
    session: BlenderSession,
    out: PathBuf,
}

impl Bench {
    /// Render `scene` into `dir` (created, emptied of old outputs); returns wall time and
    /// Cycles' render time.
    fn render(&mut self, label: &str, scene: &SceneFile, dir: &Path) -> anyhow::Result<(f64, f64)> {
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
        std::fs::write(&path, clevrtex_scene::to_pretty_json(scene)?)
            .with_context(|| format!("cannot write `{}`", path.display()))?;
        let started = Instant::now();
        let timeout = timeout_for(scene);
        let reply = self
            .session
            .request(|w| w.render_labelled(label, &path, Mode::Final, dir, timeout))
            .map_err(command_error)?;
        Ok((started.elapsed().as_secs_f64(), reply.timings.render_s))
    }
}

fn read_outputs(dir: &Path) -> anyhow::Result<Reference> {
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
    Ok(Reference {
        mean: metrics::mean(&rgb),
        rgb,
        srgb,
        mask: ch.get("ViewLayer.IndexOB.X")?.to_vec(),
        depth: ch.get("ViewLayer.Depth.Z")?.to_vec(),
    })
}

fn compare(got: &Reference, reference: &Reference, first_sample: &Reference) -> Errors {
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

fn run_render(args: RenderArgs) -> CmdResult {
    let quick = args.quick;
    let n = args.scenes.unwrap_or(if quick { 2 } else { 8 });
    let width = args.width.unwrap_or(if quick { 160 } else { 320 });
    let height = args.height.unwrap_or(if quick { 120 } else { 240 });
    let ref_samples = args
        .reference_samples
        .unwrap_or(if quick { 1024 } else { 4096 });
    if n == 0 || width == 0 || height == 0 || ref_samples == 0 {
        bail!("`--scenes`, `--width`, `--height` and `--reference-samples` must be positive\nhint: e.g. `clevrtex bench render --quick`");
    }
    if args.plot_only {
        let csv = args.out.join("bench-render.csv");
        let text = std::fs::read_to_string(&csv).with_context(|| {
            format!(
                "cannot read `{}`\nhint: run `clevrtex bench render --out {}` first",
                csv.display(),
                args.out.display()
            )
        })?;
        let rows = from_csv(&text).with_context(|| format!("bad CSV `{}`", csv.display()))?;
        let scenes: std::collections::BTreeSet<&str> =
            rows.iter().map(|r| r.scene.as_str()).collect();
        let (w, h) = rows.first().map_or((0, 0), |r| (r.width, r.height));
        return report(&rows, scenes.len(), w, h, &args.out);
    }
    let settings: Vec<Setting> = ladder::ladder(quick)
        .into_iter()
        .chain(if args.levers {
            ladder::lever_rungs(quick)
        } else {
            Vec::new()
        })
        .filter(|s| args.max_samples.is_none_or(|m| s.sampling.samples <= m))
        .filter(|s| {
            args.only
                .as_ref()
                .is_none_or(|l| l.iter().any(|w| s.label.contains(w.trim())))
        })
        .collect();
    if settings.is_empty() {
        bail!("no rung of the ladder is left after `--max-samples`/`--only`\nhint: raise `--max-samples` or widen `--only`");
    }
    if let Some(big) = settings.iter().find(|s| s.sampling.samples >= ref_samples) {
        eprintln!(
            "warning: rung `{}` has {} samples, not fewer than the reference's {ref_samples}: its error is not meaningful",
            big.label, big.sampling.samples
        );
    }
    let scenes = bench_scenes(n, width, height)?;
    std::fs::create_dir_all(&args.out).with_context(|| {
        format!(
            "cannot create output folder `{}`\nhint: pass a writable folder with `--out`",
            args.out.display()
        )
    })?;

    let blender = clevrtex_render::blender::locate(args.blender.as_deref())?;
    let catalogue = clevrtex_materials::Catalogue::builtin()
        .map_err(|e| anyhow::anyhow!("the built-in material catalogue is invalid: {e}"))?;
    let interrupt = interrupt::flag(OnInterrupt::Stop {
        message: "stopping Blender",
    });
    let mut session = BlenderSession::new(Settings {
        blender,
        materials_json: catalogue.resolved_json(),
        threads: args.threads,
        retries: args.retries,
        idle_timeout: None,
        interrupt,
        startup_timeout: crate::cmd_generate::seconds("--startup-timeout", args.startup_timeout)?,
    })?;
    let ready = session.ready()?;
    let blender_version = ready.blender_version;
    if args.levers && !ready.features.light_tree {
        bail!(
            "`--levers` needs Cycles 4.x levers, but Blender {blender_version} has none\nhint: pass a Blender 4.x or 5.x with `--blender` (e.g. `.venv-bpy/bin/python` from `./scripts/setup.sh --bpy 4.5`)"
        );
    }
    let mut bench = Bench {
        session,
        out: args.out.clone(),
    };

    println!(
        "bench render: {n} scene(s) at {width}x{height}, {} setting(s), references at {ref_samples} fixed samples; Blender {blender_version}, {} Cycles thread(s){}",
        settings.len(),
        if args.threads == 0 { "auto".to_string() } else { args.threads.to_string() },
        if quick {
            "\nquick mode: small frames, 2 scenes and fewer rungs; compare settings with it, take per-image costs from a full run"
        } else {
            ""
        }
    );
    let total = scenes.len() * settings.len();
    let mut rows = Vec::with_capacity(total);
    let mut done = 0;
    for (si, bs) in scenes.iter().enumerate() {
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
        let used = std::iter::once(bs.scene.backdrop.material.name.as_str())
            .chain(bs.scene.objects.iter().map(|o| o.material.name.as_str()));
        let recipes = catalogue.resolved_json_for(used);
        let key = clevrtex_materials::content_hash(&[
            ref_json.as_bytes(),
            recipes.as_bytes(),
            blender_version.as_bytes(),
        ]);
        let ref_dir = bench.out.join("references").join(format!("{key:016x}"));
        let reference = match read_outputs(&ref_dir) {
            Ok(r) => {
                eprintln!("[{}] reference cached in `{}`", bs.label, ref_dir.display());
                r
            }
            Err(_) => {
                eprintln!(
                    "[{}] rendering the reference ({ref_samples} samples) ...",
                    bs.label
                );
                let (wall, cycles) =
                    bench.render(&format!("{} reference", bs.label), &ref_scene, &ref_dir)?;
                eprintln!(
                    "[{}] reference took {wall:.1} s (cycles {cycles:.1} s)",
                    bs.label
                );
                read_outputs(&ref_dir)?
            }
        };
        // Mask and depth come from each pixel's first sample, so they are compared with a
        // 1-sample render at the rungs' seed: equal means no setting changes them.
        let geo_dir = ref_dir.join("first-sample");
        let geometry = match read_outputs(&geo_dir) {
            Ok(r) => r,
            Err(_) => {
                let geo_scene = with_sampling(
                    &bs.scene,
                    &Sampling {
                        samples: 1,
                        ..Sampling::ORIGINAL
                    },
                );
                bench.render(&format!("{} first sample", bs.label), &geo_scene, &geo_dir)?;
                read_outputs(&geo_dir)?
            }
        };
        for setting in &settings {
            let scene = with_sampling(&bs.scene, &setting.sampling);
            let dir = bench
                .out
                .join("runs")
                .join(format!("{si:02}-{}", setting.label));
            let label = format!("{} {}", bs.label, setting.label);
            let (wall_s, cycles_s) = bench.render(&label, &scene, &dir)?;
            let errors = compare(&read_outputs(&dir)?, &reference, &geometry);
            done += 1;
            eprintln!(
                "[{done}/{total}] {label}: {wall_s:.2} s, rel error {:.4}",
                errors.rel_error
            );
            rows.push(Row {
                scene: bs.label.clone(),
                variant: bs.scene.variant.clone(),
                width,
                height,
                setting: setting.clone(),
                wall_s,
                cycles_s,
                errors,
            });
        }
    }
    bench.session.close();

    let csv = args.out.join("bench-render.csv");
    std::fs::write(&csv, to_csv(&rows))
        .with_context(|| format!("cannot write `{}`", csv.display()))?;
    report(&rows, n, width, height, &args.out)
}

/// Table and summary on stdout, plot next to the CSV.
fn report(rows: &[Row], n: usize, width: u32, height: u32, out: &Path) -> CmdResult {
    let agg = aggregate(rows);
    print!("{}", table(&agg));
    print!("{}", summary(&agg));
    let curves = curves(&agg);
    let stem = out.join("bench-render");
    let text = plot::write(
        &stem,
        &format!("relative RMSE (linear) vs Cycles time, {n} scene(s) at {width}x{height}"),
        "Cycles render time per image (s)",
        "relative RMSE vs reference",
        &curves,
    )?;
    println!("csv: {}", out.join("bench-render.csv").display());
    println!(
        "plot: {} and {}{}",
        stem.with_extension("png").display(),
        stem.with_extension("svg").display(),
        if text {
            ""
        } else {
            " (no system font found: drawn without text; install fonts-dejavu-core)"
        }
    );
    Ok(exit::OK)
}

/// Means over scenes of one setting.
struct Agg {
    setting: Setting,
    scenes: usize,
    wall_s: f64,
    cycles_s: f64,
    rmse_linear: f64,
    rel_error: f64,
    bias: f64,
    psnr_srgb: f64,
    mask_equal: usize,
    depth_equal: usize,
}

fn aggregate(rows: &[Row]) -> Vec<Agg> {
    let mut order: Vec<String> = Vec::new();
    let mut by: BTreeMap<String, Vec<&Row>> = BTreeMap::new();
    for r in rows {
        if !by.contains_key(&r.setting.label) {
            order.push(r.setting.label.clone());
        }
        by.entry(r.setting.label.clone()).or_default().push(r);
    }
    order
        .into_iter()
        .map(|label| {
            let rs = &by[&label];
            let k = rs.len() as f64;
            let m = |f: &dyn Fn(&Row) -> f64| rs.iter().map(|r| f(r)).sum::<f64>() / k;
            Agg {
                setting: rs[0].setting.clone(),
                scenes: rs.len(),
                wall_s: m(&|r| r.wall_s),
                cycles_s: m(&|r| r.cycles_s),
                rmse_linear: m(&|r| r.errors.rmse_linear),
                rel_error: m(&|r| r.errors.rel_error),
                bias: m(&|r| r.errors.bias),
                // Mean of PSNR in dB; an identical image (infinite PSNR) would swamp it, so
                // it counts as 99 dB.
                psnr_srgb: m(&|r| r.errors.psnr_srgb.min(99.0)),
                mask_equal: rs.iter().filter(|r| r.errors.mask_equal).count(),
                depth_equal: rs.iter().filter(|r| r.errors.depth_equal).count(),
            }
        })
        .collect()
}

fn threshold_text(s: &Sampling) -> String {
    s.adaptive_threshold
        .map_or_else(|| "-".to_string(), |t| t.to_string())
}

fn table(agg: &[Agg]) -> String {
    let mut s = String::new();
    let _ = writeln!(
        s,
        "\n{:<30} {:>5} {:>6} {:>7} {:>5} {:>8} {:>8} {:>9} {:>8} {:>7} {:>6} {:>5} {:>5}",
        "setting",
        "spp",
        "thresh",
        "bounce",
        "clamp",
        "wall s",
        "cycles s",
        "rmse lin",
        "rel err",
        "bias",
        "psnr",
        "mask",
        "depth"
    );
    for a in agg {
        let p = &a.setting.sampling;
        let _ = writeln!(
            s,
            "{:<30} {:>5} {:>6} {:>7} {:>5} {:>8.2} {:>8.2} {:>9.5} {:>8.4} {:>+7.4} {:>6.2} {:>5} {:>5}",
            a.setting.label,
            p.samples,
            threshold_text(p),
            format!("{}/{}/{}", p.max_bounces, p.diffuse_bounces, p.glossy_bounces),
            p.clamp_indirect,
            a.wall_s,
            a.cycles_s,
            a.rmse_linear,
            a.rel_error,
            a.bias,
            a.psnr_srgb,
            format!("{}/{}", a.mask_equal, a.scenes),
            format!("{}/{}", a.depth_equal, a.scenes),
        );
    }
    s.push_str("(means over scenes; bounce = max/diffuse/glossy; rel err = RMSE / mean of the reference, linear light; bias = relative difference of the means; psnr in dB on the 8-bit sRGB PNG; mask/depth = scenes whose pass equals that of a 1-sample render at the same seed exactly; references use another Cycles seed)\n");
    s
}

fn summary(agg: &[Agg]) -> String {
    let mut s = String::new();
    let Some(orig) = agg.iter().find(|a| a.setting.label == "original-512") else {
        return s;
    };
    let _ = writeln!(
        s,
        "\noriginal (512 fixed samples, its bounces): rel error {:.4}, wall {:.2} s, cycles {:.2} s per image",
        orig.rel_error, orig.wall_s, orig.cycles_s
    );
    let _ = writeln!(
        s,
        "settings at most as noisy as the original (rel error <= original's), by wall time:"
    );
    let mut better: Vec<&Agg> = agg
        .iter()
        .filter(|a| a.setting.label != orig.setting.label && a.rel_error <= orig.rel_error)
        .collect();
    better.sort_by(|a, b| a.wall_s.total_cmp(&b.wall_s));
    if better.is_empty() {
        let _ = writeln!(s, "  (none)");
    }
    for a in better {
        let _ = writeln!(
            s,
            "  {:<30} wall x{:.2} of the original, rel error {:.4}, bias {:+.4}",
            a.setting.label,
            a.wall_s / orig.wall_s.max(1e-9),
            a.rel_error,
            a.bias
        );
    }
    for q in Quality::ALL {
        let Some(a) = agg.iter().find(|a| a.setting.sampling == q.settings()) else {
            continue;
        };
        let ratio = a.wall_s / orig.wall_s.max(1e-9);
        let _ = write!(
            s,
            "preset {q} (= {}): wall {:.2} s, x{ratio:.2} of the original; rel error {:.4} vs {:.4}; bias {:+.4}",
            a.setting.label, a.wall_s, a.rel_error, orig.rel_error, a.bias
        );
        if q == Quality::Standard {
            let ok = a.rel_error <= orig.rel_error && ratio <= 0.5;
            let _ = write!(
                s,
                " (target: error <= original's in <= 0.50 of its time: {})",
                if ok { "met" } else { "NOT met" }
            );
        }
        s.push('\n');
    }
    s
}

fn curves(agg: &[Agg]) -> Vec<plot::Curve> {
    let mut by: BTreeMap<&str, Vec<(f64, f64)>> = BTreeMap::new();
    for a in agg {
        by.entry(a.setting.mode)
            .or_default()
            .push((a.cycles_s, a.rel_error));
    }
    by.into_iter().map(|(k, v)| (k.to_string(), v)).collect()
}

const CSV_HEADER: &str = "scene,variant,setting,mode,width,height,samples,adaptive_threshold,max_bounces,diffuse_bounces,glossy_bounces,transmission_bounces,transparent_max_bounces,clamp_indirect,wall_s,cycles_s,rmse_linear,rel_error,bias,psnr_srgb,mask_equal,depth_equal";

fn to_csv(rows: &[Row]) -> String {
    let mut s = format!("{CSV_HEADER}\n");
    for r in rows {
        let p = &r.setting.sampling;
        let _ = writeln!(
            s,
            "{},{},{},{},{},{},{},{},{},{},{},{},{},{},{:.4},{:.4},{:.6},{:.6},{:.6},{},{},{}",
            r.scene,
            r.variant,
            r.setting.label,
            r.setting.mode,
            r.width,
            r.height,
            p.samples,
            p.adaptive_threshold
                .map_or(String::new(), |t| t.to_string()),
            p.max_bounces,
            p.diffuse_bounces,
            p.glossy_bounces,
            p.transmission_bounces,
            p.transparent_max_bounces,
            p.clamp_indirect,
            r.wall_s,
            r.cycles_s,
            r.errors.rmse_linear,
            r.errors.rel_error,
            r.errors.bias,
            if r.errors.psnr_srgb.is_finite() {
                format!("{:.3}", r.errors.psnr_srgb)
            } else {
                "inf".to_string()
            },
            r.errors.mask_equal,
            r.errors.depth_equal,
        );
    }
    s
}

/// Rows back from [`to_csv`]'s output.
fn from_csv(text: &str) -> anyhow::Result<Vec<Row>> {
    let mut lines = text.lines();
    if lines.next() != Some(CSV_HEADER) {
        bail!("unexpected header\nhint: the CSV must come from this version's `clevrtex bench render`");
    }
    lines
        .enumerate()
        .map(|(i, line)| {
            let c: Vec<&str> = line.split(',').collect();
            if c.len() != 22 {
                bail!("line {}: {} cells, expected 22", i + 2, c.len());
            }
            let f = |k: usize| -> anyhow::Result<f64> {
                if c[k] == "inf" {
                    return Ok(f64::INFINITY);
                }
                c[k].parse()
                    .with_context(|| format!("line {}: bad number `{}`", i + 2, c[k]))
            };
            let u = |k: usize| f(k).map(|v| v as u32);
            let mode = [
                "fixed",
                "adaptive",
                "adaptive-lowbounce",
                "adaptive-clamp",
                "preset",
                "notree",
                "guiding",
                "bluenoise",
                "oidn",
                "oidn-notree",
            ]
            .into_iter()
            .find(|m| *m == c[3])
            .unwrap_or("other");
            Ok(Row {
                scene: c[0].to_string(),
                variant: c[1].to_string(),
                width: u(4)?,
                height: u(5)?,
                setting: Setting {
                    mode,
                    label: c[2].to_string(),
                    sampling: Sampling {
                        samples: u(6)?,
                        adaptive_threshold: if c[7].is_empty() {
                            None
                        } else {
                            Some(f(7)? as f32)
                        },
                        max_bounces: u(8)?,
                        diffuse_bounces: u(9)?,
                        glossy_bounces: u(10)?,
                        transmission_bounces: u(11)?,
                        transparent_max_bounces: u(12)?,
                        clamp_indirect: f(13)? as f32,
                        // Not in the CSV: the lever rungs are known by their labels.
                        levers: ladder::lever_rungs(false)
                            .into_iter()
                            .chain(ladder::lever_rungs(true))
                            .find(|s| s.label == c[2])
                            .map_or(clevrtex_scene::quality::Levers::NONE, |s| s.sampling.levers),
                    },
                },
                wall_s: f(14)?,
                cycles_s: f(15)?,
                errors: Errors {
                    rmse_linear: f(16)?,
                    rel_error: f(17)?,
                    bias: f(18)?,
                    psnr_srgb: f(19)?,
                    mask_equal: c[20] == "true",
                    depth_equal: c[21] == "true",
                },
            })
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn csv_round_trips() {
        let s = ladder::ladder(true).remove(5);
        let row = Row {
            scene: "full#0".into(),
            variant: "full".into(),
            width: 160,
            height: 120,
            setting: s.clone(),
            wall_s: 1.5,
            cycles_s: 1.25,
            errors: Errors {
                rmse_linear: 0.125,
                rel_error: 0.5,
                bias: -0.25,
                psnr_srgb: f64::INFINITY,
                mask_equal: true,
                depth_equal: false,
            },
        };
        let text = to_csv(std::slice::from_ref(&row));
        let back = from_csv(&text).unwrap();
        assert_eq!(back.len(), 1);
        let b = &back[0];
        assert_eq!(b.setting, s);
        assert_eq!(
            (b.width, b.height, b.wall_s, b.cycles_s),
            (160, 120, 1.5, 1.25)
        );
        assert_eq!(b.errors, row.errors);
        assert_eq!(to_csv(&back), text);
        assert!(from_csv("nope\n")
            .unwrap_err()
            .to_string()
            .contains("hint:"));
    }

    #[test]
    fn bench_scenes_are_fixed_and_cover_variants() {
        let a = bench_scenes(3, 64, 48).unwrap();
        let b = bench_scenes(3, 64, 48).unwrap();
        assert_eq!(a.len(), 3);
        for (x, y) in a.iter().zip(&b) {
            assert_eq!(x.scene, y.scene);
            assert_eq!((x.scene.render.width, x.scene.render.height), (64, 48));
            assert_eq!(x.scene.passes, vec![Pass::Rgb, Pass::Mask, Pass::Depth]);
        }
        assert_eq!(
            a.iter().map(|s| s.label.as_str()).collect::<Vec<_>>(),
            ["full#0", "camo#1", "pbg#2"]
        );
    }
}
