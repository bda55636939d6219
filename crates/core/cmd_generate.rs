//! `clevrtex generate`: glue between the command line, the sampler (`clevrtex-scene`) and the
//! render pool (`clevrtex-render`); also what `generate` and `render` (`cmd_render.rs`) share:
//! their run options ([`RunArgs`]), `--passes` ([`parse_passes`]) and the pool run with its
//! progress and summary ([`run_jobs`]).

use std::collections::BTreeMap;
use std::io::IsTerminal;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::Arc;
use std::time::Duration;

use anyhow::{bail, Context};
use clevrtex_render::manifest::Manifest;
use clevrtex_render::pool::{self, Job, PoolEvent, PoolOptions, RunReport};
use clevrtex_render::RenderError;
use clevrtex_scene::{layout, Config, Pass, SampleRequest};
use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};

use crate::exit::{self, CmdResult};
use crate::interrupt::{self, OnInterrupt};

/// Options shared by `generate` and `render`: how to run Blender and write the output.
#[derive(Debug, clap::Args)]
pub struct RunArgs {
    /// Output root; samples go to `OUT/clevrtex_<variant>/<index / 1000>/`.
    #[arg(long, value_name = "OUT")]
    pub(crate) out: PathBuf,
    /// Passes to write, comma-separated: rgb,mask,depth,normal,albedo,shadow (default all
    /// for `generate`; the scene files' own list for `render`).
    #[arg(long, value_delimiter = ',', value_name = "LIST")]
    pub(crate) passes: Option<Vec<String>>,
    /// Blender: an executable, or a Python that imports `bpy` (default: `blender` on PATH, else
    /// `./.venv-bpy/bin/python`).
    #[arg(long, env = "CLEVRTEX_BLENDER", value_name = "PATH")]
    blender: Option<PathBuf>,
    /// Blender processes rendering in parallel (default: 2 on machines with 2+ cores).
    #[arg(long, value_name = "N")]
    workers: Option<usize>,
    /// Cycles device: `auto` (the best GPU kind Blender reports: OptiX, CUDA, HIP; else the
    /// CPU), `cpu`, `cuda`, `optix` or `hip`. With N GPUs, one worker per GPU (pinned by its
    /// index) and `--workers` defaults to N.
    #[arg(long, default_value = "auto", value_name = "DEVICE")]
    device: String,
    /// Cycles threads per Blender process (default: cores / workers).
    #[arg(long, value_name = "T")]
    threads: Option<u32>,
    /// Time limit per render request, seconds; a worker over it is killed and the scene
    /// retried. Default: 600 + 8 per sample at 320x240 (doubled with the shadow pass), and
    /// a worker silent for 300 s counts as hung.
    #[arg(long, value_name = "SECONDS")]
    timeout: Option<f64>,
    /// Time limit for a Blender worker to start (load the bridge and answer `ready`), seconds.
    #[arg(long, default_value_t = clevrtex_render::STARTUP_TIMEOUT.as_secs_f64(), value_name = "SECONDS")]
    startup_timeout: f64,
    /// Restarts of a crashed or hung worker per scene before it goes to the failure ledger.
    #[arg(long, default_value_t = 2, value_name = "N")]
    retries: u32,
    /// Also keep the float EXRs (`<stem>_passes.exr`, and with the shadow pass
    /// `<stem>_shadow.exr`).
    #[arg(long)]
    keep_exr: bool,
    /// Redo samples that are already complete (default: skip them, i.e. resume).
    #[arg(long)]
    overwrite: bool,
    /// Stop at the first failed scene instead of recording it in the ledger and going on.
    #[arg(long)]
    fail_fast: bool,
}

/// Arguments of `clevrtex generate`.
#[derive(Debug, clap::Args)]
#[command(after_help = crate::shard::SHARD_HELP)]
pub struct GenerateArgs {
    #[arg(long, default_value = "full", conflicts_with = "config",
        help = format!("Built-in variant: {}", Config::variant_list()))]
    variant: String,
    /// A variant config file (JSON, like those in `configs/`) instead of `--variant`.
    #[arg(long, value_name = "FILE")]
    config: Option<PathBuf>,
    /// Number of images.
    #[arg(short = 'n', long = "count", value_name = "N")]
    count: u64,
    /// Run seed: with the image index it fixes every random draw.
    #[arg(long, default_value_t = 0)]
    seed: u64,
    /// First image index; images `START..START+N` are made.
    #[arg(long, default_value_t = 0, value_name = "I")]
    start: u64,
    /// Size of the whole dataset, which fixes the splits (first 10% test, next 10% val, rest
    /// train) [default: START + N].
    #[arg(long, value_name = "T")]
    total: Option<u64>,
    /// Make only the images with `index % N == K` (0 <= K < N), as `clevrtex sample` does:
    /// N shards together make every image exactly once.
    #[arg(long, value_name = "K/N")]
    shard: Option<String>,
    /// Number of shards when the shard index comes from JOB_COMPLETION_INDEX.
    #[arg(long, value_name = "N", env = "CLEVRTEX_SHARD_COUNT")]
    shard_count: Option<u64>,
    /// Image width in pixels (default 320).
    #[arg(long)]
    width: Option<u32>,
    /// Image height in pixels (default 240).
    #[arg(long)]
    height: Option<u32>,
    /// Cycles samples per pixel (default from the config).
    #[arg(long)]
    samples: Option<u32>,
    /// Samples of the shadow pass's render (default: three eighths of the samples, at most
    /// 64; RMSE ~0.018 at 8, ~0.010 at 16, ~0.008 at 24; docs/performance.md, "Shadow pass").
    #[arg(long, value_name = "N")]
    shadow_samples: Option<u32>,
    /// Quality preset: draft, standard, high or reference (samples, adaptive threshold,
    /// bounces; see docs/performance.md). `--samples` still overrides the sample count.
    #[arg(long, value_name = "PRESET")]
    quality: Option<clevrtex_scene::quality::Quality>,
    /// Layout attempts per image when objects are hidden, before the image fails.
    #[arg(long, default_value_t = 20, value_name = "N")]
    max_attempts: u32,
    #[command(flatten)]
    run: RunArgs,
}

/// Layouts drawn by `generate` before any Blender starts, to refuse impossible configs.
const PREFLIGHT_LAYOUTS: usize = 20;

/// Run `clevrtex generate`.
pub fn run_generate(args: GenerateArgs) -> CmdResult {
    let mut config = match &args.config {
        Some(path) => {
            let text = std::fs::read_to_string(path).map_err(|e| {
                anyhow::anyhow!(
                    "cannot read config `{}`: {e}\nhint: pass an existing JSON file, e.g. one of `configs/`",
                    path.display()
                )
            })?;
            Config::from_json_str(&text, &path.display().to_string())?
        }
        None => Config::builtin(&args.variant)?,
    };
    use clevrtex_scene::scene_file::{MAX_IMAGE_SIDE, MAX_SAMPLES};
    if let Some(w) = args.width {
        config.base.render.width = within("--width", w, MAX_IMAGE_SIDE)?;
    }
    if let Some(h) = args.height {
        config.base.render.height = within("--height", h, MAX_IMAGE_SIDE)?;
    }
    if let Some(q) = args.quality {
        q.apply(&mut config.base.render);
    }
    if let Some(s) = args.samples {
        config.base.render.samples = within("--samples", s, MAX_SAMPLES)?;
    }
    if let Some(s) = args.shadow_samples {
        config.base.render.shadow_samples = Some(within("--shadow-samples", s, MAX_SAMPLES)?);
    }
    positive("--max-attempts", args.max_attempts)?;
    // Fail before starting Blender when no layout could ever be drawn, as `sample` does.
    clevrtex_scene::sample::check_feasible(&config)?;
    let passes = match &args.run.passes {
        Some(list) => parse_passes(list)?,
        None => Pass::ALL.to_vec(),
    };
    config.base.passes = passes.clone();
    if args.count == 0 {
        bail!("`-n 0` asks for no images\nhint: pass the number of images, e.g. `-n 100`");
    }
    let end = args
        .start
        .checked_add(args.count)
        .context("`--start` + `-n` overflows\nhint: pass smaller numbers")?;
    let total = args.total.unwrap_or(end);
    if total < end {
        bail!("`--total {total}` is smaller than the last index + 1 (`{end}`)\nhint: pass the size of the whole dataset");
    }
    let range =
        crate::shard::resolve(args.shard.as_deref(), args.shard_count)?.indices(args.start, end);
    // Draw the first layouts before starting Blender: a config whose objects can never be
    // placed fails here once (exit 1), as in `sample`, not once per image into the ledger.
    for &index in range.iter().take(PREFLIGHT_LAYOUTS) {
        let req = SampleRequest {
            seed: args.seed,
            index,
            attempt: 0,
            total,
        };
        clevrtex_scene::sample(&config, &req)?;
    }
    let config = Arc::new(config);
    let variant = config.name.clone();
    let jobs: Vec<Job> = range
        .into_iter()
        .map(|index| {
            let config = Arc::clone(&config);
            let seed = args.seed;
            Job {
                index,
                variant: variant.clone(),
                stem: clevrtex_scene::stem(&variant, index),
                passes: passes.clone(),
                scene: Arc::new(move |attempt| {
                    clevrtex_scene::sample(
                        &config,
                        &SampleRequest {
                            seed,
                            index,
                            attempt,
                            total,
                        },
                    )
                    .map_err(|e| e.to_string())
                }),
                resample: true,
                source: None,
            }
        })
        .collect();
    let ledger = layout::variant_dir(&args.run.out, &variant).join("failures.jsonl");
    let shard = crate::shard::resolve(args.shard.as_deref(), args.shard_count)?;
    let plan = ManifestPlan {
        variant: variant.clone(),
        seed: args.seed,
        config_hash: clevrtex_render::manifest::hash_hex(format!("{config:?}").as_bytes()),
        start: args.start,
        end,
        total,
        shard: [shard.k, shard.n],
        passes: passes.clone(),
        keep_exr: args.run.keep_exr,
    };
    run_jobs(&args.run, jobs, ledger, args.max_attempts, Some(plan))
}

/// What `generate` records in its run manifest (`clevrtex_render::manifest`).
pub(crate) struct ManifestPlan {
    variant: String,
    seed: u64,
    config_hash: String,
    start: u64,
    end: u64,
    total: u64,
    shard: [u64; 2],
    passes: Vec<Pass>,
    keep_exr: bool,
}

impl ManifestPlan {
    fn variant_dir(&self, out: &Path) -> PathBuf {
        layout::variant_dir(out, &self.variant)
    }

    /// The manifest of this run's range and shard as an earlier run left it, if readable.
    fn earlier(&self, out: &Path) -> Option<Manifest> {
        let name = clevrtex_render::manifest::file_name(
            self.start,
            self.end,
            self.shard[0],
            self.shard[1],
        );
        Manifest::read(&self.variant_dir(out).join(name)).ok()
    }

    /// The manifest with these settings, `files` and `sample_seconds`.
    fn manifest(
        &self,
        finished: bool,
        blender_version: String,
        files: BTreeMap<String, clevrtex_render::manifest::FileEntry>,
        sample_seconds: BTreeMap<String, f64>,
    ) -> Manifest {
        Manifest {
            format: clevrtex_render::manifest::MANIFEST_FORMAT.into(),
            version: clevrtex_render::manifest::MANIFEST_VERSION,
            variant: self.variant.clone(),
            seed: self.seed,
            config_hash: self.config_hash.clone(),
            start: self.start,
            end: self.end,
            total: self.total,
            shard: self.shard,
            passes: self.passes.iter().map(|p| p.name().to_string()).collect(),
            tool_version: env!("CARGO_PKG_VERSION").into(),
            blender_version,
            command: std::env::args().collect(),
            finished,
            files,
            sample_seconds,
        }
    }

    /// Write the run's plan before the first image: its manifest with `finished: false` and
    /// no files, so `verify` knows what the run is to make even if it never ends. The seconds
    /// of samples an earlier run of this range made are kept.
    fn write_plan(&self, out: &Path) -> anyhow::Result<PathBuf> {
        let seconds = self
            .earlier(out)
            .map(|m| m.sample_seconds)
            .unwrap_or_default();
        let m = self.manifest(false, String::new(), BTreeMap::new(), seconds);
        let vdir = self.variant_dir(out);
        std::fs::create_dir_all(&vdir).with_context(|| {
            format!(
                "cannot create `{}`\nhint: pass a writable folder with `--out`",
                vdir.display()
            )
        })?;
        Ok(m.write(&vdir)?)
    }

    /// Write the manifest of the run's complete samples (hashing their files).
    /// `seconds`: time per sample made by this run, by index; those of complete samples an
    /// earlier run made are kept from its manifest.
    fn write(&self, out: &Path, seconds: &BTreeMap<u64, f64>) -> anyhow::Result<PathBuf> {
        let vdir = self.variant_dir(out);
        let earlier = self
            .earlier(out)
            .map(|m| m.sample_seconds)
            .unwrap_or_default();
        let mut sample_seconds = BTreeMap::new();
        let shard = crate::shard::Shard {
            k: self.shard[0],
            n: self.shard[1],
        };
        let mut files = Vec::new();
        let mut blender_version = String::new();
        for index in shard.iter(self.start, self.end) {
            let stem = layout::stem(&self.variant, index);
            let dir = layout::sample_dir(out, &self.variant, index);
            let names = clevrtex_render::output::expected_files(&stem, &self.passes, self.keep_exr);
            if !names.iter().all(|n| dir.join(n).is_file()) {
                continue;
            }
            if blender_version.is_empty() {
                let meta =
                    std::fs::read(dir.join(layout::metadata_file(&stem))).unwrap_or_default();
                let meta: serde_json::Value = serde_json::from_slice(&meta).unwrap_or_default();
                blender_version = meta["blender_version"].as_str().unwrap_or("").to_string();
            }
            if let Some(s) = seconds.get(&index).or_else(|| earlier.get(&stem)) {
                sample_seconds.insert(stem.clone(), (s * 1000.0).round() / 1000.0);
            }
            let sub = (index / 1000).to_string();
            files.extend(names.into_iter().map(|n| format!("{sub}/{n}")));
        }
        let files = clevrtex_render::manifest::hash_files(&vdir, &files)?;
        let manifest = self.manifest(true, blender_version, files, sample_seconds);
        Ok(manifest.write(&vdir)?)
    }
}

fn positive(flag: &str, v: u32) -> anyhow::Result<u32> {
    if v == 0 {
        bail!("`{flag} 0` is not allowed\nhint: pass a positive number");
    }
    Ok(v)
}

/// A positive, finite number of seconds given as `flag`.
pub(crate) fn seconds(flag: &str, v: f64) -> anyhow::Result<Duration> {
    if !(v > 0.0 && v.is_finite()) {
        bail!("`{flag} {v}` must be a positive number of seconds\nhint: e.g. `{flag} 120`");
    }
    Ok(Duration::from_secs_f64(v))
}

fn within(flag: &str, v: u32, max: u32) -> anyhow::Result<u32> {
    if v > max {
        bail!("`{flag} {v}` is more than the {max} allowed\nhint: pass 1 to {max}");
    }
    positive(flag, v)
}

pub(crate) fn parse_passes(list: &[String]) -> anyhow::Result<Vec<Pass>> {
    let mut out = Vec::new();
    for name in list.iter().map(|s| s.trim()).filter(|s| !s.is_empty()) {
        match Pass::from_name(name) {
            Some(p) if !out.contains(&p) => out.push(p),
            Some(_) => {}
            None => bail!(
                "unknown pass `{name}`\nhint: use a comma-separated list of {}",
                Pass::ALL.map(Pass::name).join(", ")
            ),
        }
    }
    if out.is_empty() {
        bail!(
            "`--passes` is empty\nhint: name at least one of {}",
            Pass::ALL.map(Pass::name).join(", ")
        );
    }
    out.sort();
    Ok(out)
}

pub(crate) fn run_jobs(
    args: &RunArgs,
    jobs: Vec<Job>,
    ledger: PathBuf,
    max_attempts: u32,
    manifest: Option<ManifestPlan>,
) -> CmdResult {
    let blender = clevrtex_render::blender::locate(args.blender.as_deref())?;
    check_output_writable(&args.out)?;
    let materials_json = clevrtex_render::default_materials_json()
        .map_err(|e| anyhow::anyhow!("the built-in material catalogue is invalid: {e}"))?;
    let interrupt = interrupt::flag(OnInterrupt::Stop {
        message: "stopping the workers; finished samples are kept",
    });
    if let Some(t) = args.timeout {
        if !(t > 0.0 && t.is_finite()) {
            bail!(
                "`--timeout {t}` must be a positive number of seconds\nhint: e.g. `--timeout 600`"
            );
        }
    }
    if args.workers == Some(0) {
        bail!("`--workers 0` cannot render anything\nhint: pass at least 1");
    }
    let devices = plan_devices(args, &blender, &materials_json, &interrupt)?;
    if devices.iter().any(|d| d.is_gpu()) {
        let names: Vec<String> = devices.iter().map(|d| d.describe()).collect();
        eprintln!("devices: {}", names.join(", "));
    }
    let opts = PoolOptions {
        blender,
        materials_json,
        workers: args.workers.unwrap_or_else(|| {
            clevrtex_render::device::default_workers(&devices, pool::default_workers())
        }),
        threads: args.threads.unwrap_or(0),
        timeout: args.timeout.map(Duration::from_secs_f64),
        startup_timeout: seconds("--startup-timeout", args.startup_timeout)?,
        retries: args.retries,
        max_attempts: max_attempts.max(1),
        visibility_check: true,
        keep_exr: args.keep_exr,
        overwrite: args.overwrite,
        fail_fast: args.fail_fast,
        out: args.out.clone(),
        ledger: ledger.clone(),
        interrupt: Arc::clone(&interrupt),
        devices: devices.clone(),
    };
    let total = jobs.len() as u64;
    let bar = progress_bar(total);
    let (done, rejects, failures) = (AtomicU64::new(0), AtomicU64::new(0), AtomicU64::new(0));
    let started = std::time::Instant::now();
    // Seconds per finished sample, by index, for the manifest (`clevrtex report` plots them).
    let seconds = std::sync::Mutex::new(std::collections::BTreeMap::<u64, f64>::new());
    let plain = bar.is_hidden();
    // A hidden bar swallows `println`: then messages go straight to stderr.
    let say = |msg: String| {
        if plain {
            eprintln!("{msg}");
        } else {
            bar.println(msg);
        }
    };
    let on_event = |ev: &PoolEvent| {
        match ev {
            PoolEvent::Skipped { .. } => bar.inc(1),
            PoolEvent::WorkerStarted { .. } => {}
            PoolEvent::WorkerRestarted { error } => {
                say(format!("warning: restarting a Blender worker: {error}"));
            }
            PoolEvent::Rejected { .. } => {
                rejects.fetch_add(1, Ordering::Relaxed);
            }
            PoolEvent::Done { sample } => {
                let d = done.fetch_add(1, Ordering::Relaxed) + 1;
                let s =
                    sample.visibility_s + sample.reject_s + sample.final_request_s + sample.post_s;
                seconds
                    .lock()
                    .unwrap_or_else(|e| e.into_inner())
                    .insert(sample.index, s);
                bar.inc(1);
                if plain {
                    eprintln!(
                        "[{}/{}] wrote {}",
                        bar.position(),
                        total,
                        sample.metadata.display()
                    );
                }
                // Only fixed scene files (`render`) can get here with a hidden object:
                // `generate` resamples such layouts.
                let hidden: Vec<String> = (1..)
                    .zip(&sample.objects)
                    .filter(|(_, o)| o.pixels == 0)
                    .map(|(i, _)| i.to_string())
                    .collect();
                if !hidden.is_empty() {
                    say(format!(
                        "warning: object(s) {} of `{}` are hidden (not in the mask)\nhint: `clevrtex render` cannot resample fixed scene files; use `clevrtex generate` for layouts with every object visible",
                        hidden.join(", "),
                        sample.metadata.display()
                    ));
                }
                let _ = d;
            }
            PoolEvent::Failed { index, error } => {
                failures.fetch_add(1, Ordering::Relaxed);
                bar.inc(1);
                say(format!(
                    "error: image {index} failed (recorded in `{}`): {error}",
                    ledger.display()
                ));
            }
        }
        let d = done.load(Ordering::Relaxed);
        let per_hour = d as f64 / started.elapsed().as_secs_f64().max(1e-9) * 3600.0;
        bar.set_message(format!(
            "{per_hour:.0} img/h, {} rejects, {} failed",
            rejects.load(Ordering::Relaxed),
            failures.load(Ordering::Relaxed)
        ));
    };
    // One writer per range: a run whose indices overlap a live run's refuses here, before
    // anything is written; then the plan, so even a run that never ends is known to `verify`.
    let _lock = match &manifest {
        Some(plan) => {
            let lock = clevrtex_render::run_lock::RunLock::acquire(
                &plan.variant_dir(&args.out),
                plan.start,
                plan.end,
                plan.shard,
                std::env::args().collect(),
            )
            .map_err(|e| anyhow::anyhow!(e))?;
            plan.write_plan(&args.out)?;
            Some(lock)
        }
        None => None,
    };
    let result = pool::run(&opts, jobs, &on_event);
    bar.finish_and_clear();
    match result {
        Ok(report) => {
            print_summary(&report, &args.out, &ledger);
            if let Some(plan) = manifest {
                let seconds = seconds.into_inner().unwrap_or_else(|e| e.into_inner());
                let path = plan.write(&args.out, &seconds)?;
                println!(
                    "manifest: {} (check with `clevrtex verify {}`)",
                    path.display(),
                    args.out.display()
                );
            }
            Ok(if report.failed.is_empty() {
                exit::OK
            } else {
                exit::PARTIAL
            })
        }
        Err(RenderError::Interrupted) => {
            eprintln!(
                "error: {}\nhint: rerun the same command to go on; complete samples are skipped",
                exit::Interrupted
            );
            Ok(crate::interrupt::exit_code())
        }
        Err(e) => Err(e.into()),
    }
}

fn progress_bar(total: u64) -> ProgressBar {
    let target = if std::io::stderr().is_terminal() {
        ProgressDrawTarget::stderr()
    } else {
        ProgressDrawTarget::hidden()
    };
    let bar = ProgressBar::with_draw_target(Some(total), target);
    bar.set_style(
        ProgressStyle::with_template("{bar:24} {pos}/{len} images, {msg}, ETA {eta}")
            .expect("valid template"),
    );
    bar.set_message("0 img/h, 0 rejects, 0 failed");
    bar.enable_steady_tick(Duration::from_millis(500));
    bar
}

/// Make sure the output root exists and a file can be created in it, before any rendering.
fn check_output_writable(out: &Path) -> anyhow::Result<()> {
    let hint = "hint: pass a writable folder with `--out`";
    std::fs::create_dir_all(out).map_err(|e| {
        anyhow::anyhow!(
            "cannot create output folder `{}`: {e}\n{hint}",
            out.display()
        )
    })?;
    let probe = out.join(format!(".clevrtex-write-test-{}", std::process::id()));
    std::fs::write(&probe, b"").map_err(|e| {
        anyhow::anyhow!(
            "cannot write in output folder `{}`: {e}\n{hint}",
            out.display()
        )
    })?;
    let _ = std::fs::remove_file(probe);
    Ok(())
}

fn print_summary(r: &RunReport, out: &Path, ledger: &Path) {
    println!(
        "rendered {} images ({} already complete, {} failed) in {:.1} s with {} worker(s) x {} thread(s)",
        r.done,
        r.skipped,
        r.failed.len(),
        r.wall_s,
        r.workers,
        r.threads
    );
    if r.done > 0 {
        println!(
            "  {:.1} s per image, {:.0} images/hour",
            r.wall_s / r.done as f64,
            r.done as f64 / r.wall_s.max(1e-9) * 3600.0
        );
    }
    println!("time split (summed over workers):");
    println!(
        "  blender start    {:>8.1} s  ({} start(s))",
        r.blender_start_s, r.worker_starts
    );
    println!("  scene build      {:>8.1} s", r.build_s);
    println!(
        "  visibility pass  {:>8.1} s  (all {} passes incl. rejected: build {:.1} s, cycles {:.1} s)",
        r.visibility_s, r.visibility_passes, r.visibility_build_s, r.visibility_render_s
    );
    println!("  render (cycles)  {:>8.1} s", r.render_s);
    println!(
        "  bridge other     {:>8.1} s  (writing EXR/PNG in Blender, protocol)",
        (r.final_request_s - r.render_s - r.build_s).max(0.0)
    );
    println!("  post-processing  {:>8.1} s", r.post_s);
    println!(
        "  rejects          {:>8.1} s  ({} rejected layout(s); checked after the full render they would have cost ~{:.1} s)",
        r.reject_s,
        r.rejects,
        r.rejects_cost_if_checked_after()
    );
    if let Some(ratio) = r.overhead_ratio() {
        println!("  overhead: wall x workers / cycles render = {ratio:.3}");
    }
    println!("output: {}", out.display());
    if r.ledger_unreadable > 0 {
        eprintln!(
            "warning: dropped {} unreadable line(s) of the failure ledger `{}` (left by a run killed while writing it); rerun without `--overwrite` to find what is still missing",
            r.ledger_unreadable,
            ledger.display()
        );
    }
    if !r.failed.is_empty() {
        println!(
            "failures recorded in `{}`; rerun the same command to retry them",
            ledger.display()
        );
    }
}

/// The devices the workers are spread over (`--device`): the CPU for `cpu`, and for `auto` on a
/// machine without GPU device files; otherwise a first worker is asked which GPUs Cycles sees
/// and [`clevrtex_render::device::plan`] chooses. For `auto`, a worker that does not start
/// means the CPU (the pool then reports the start failure itself).
fn plan_devices(
    args: &RunArgs,
    blender: &std::path::Path,
    materials_json: &str,
    interrupt: &std::sync::Arc<std::sync::atomic::AtomicBool>,
) -> anyhow::Result<Vec<clevrtex_render::device::Placement>> {
    use clevrtex_render::device::{self, DeviceChoice, Placement};
    let Some(choice) = DeviceChoice::parse(&args.device) else {
        bail!(
            "unknown device `{}`\nhint: use one of {}",
            args.device,
            DeviceChoice::ALL.map(|(_, n)| n).join(", ")
        );
    };
    if choice == DeviceChoice::Cpu
        || (choice == DeviceChoice::Auto && !device::gpu_hardware_present())
    {
        return Ok(vec![Placement::cpu()]);
    }
    let bridge = clevrtex_render::BridgeDir::create(materials_json)?;
    let started = clevrtex_render::Worker::start(&clevrtex_render::WorkerOptions {
        blender: blender.to_path_buf(),
        script: bridge.worker_script(),
        materials: bridge.materials_json(),
        threads: 1,
        startup_timeout: seconds("--startup-timeout", args.startup_timeout)?,
        interrupt: std::sync::Arc::clone(interrupt),
        device: Placement::cpu(),
    });
    let gpus = match started {
        Ok(worker) => {
            let gpus = worker.ready().gpus.clone();
            worker.quit();
            gpus
        }
        Err(_) if choice == DeviceChoice::Auto => return Ok(vec![Placement::cpu()]),
        Err(e) => return Err(e.into()),
    };
    device::plan(choice, &gpus).map_err(|e| anyhow::anyhow!(e))
}
