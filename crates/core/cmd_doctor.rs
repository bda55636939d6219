//! `clevrtex doctor`: what Blender is found, its version, its Cycles devices, whether the
//! embedded bridge starts in it, and what is missing.

use std::path::PathBuf;
use std::sync::atomic::AtomicBool;
use std::sync::Arc;
use std::time::Duration;

use clevrtex_render::{blender, BridgeDir, Worker, WorkerOptions};

use crate::exit::{self, CmdResult};

/// The Blender version the bridge is developed and tested against.
const TARGET: (u32, u32) = (3, 4);

/// Arguments of `clevrtex doctor`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// Blender executable to check (default: `blender` on PATH).
    #[arg(long, env = "CLEVRTEX_BLENDER", value_name = "PATH")]
    blender: Option<PathBuf>,
    /// Seconds each check may take (`blender --version`, the bridge's start-up) before the
    /// program is killed and reported.
    #[arg(long, default_value_t = 60.0, value_name = "SECS")]
    timeout: f64,
}

/// Run `clevrtex doctor`.
pub fn run(args: Args) -> CmdResult {
    println!("clevrtex {}", env!("CARGO_PKG_VERSION"));
    let cores = clevrtex_render::pool::available_cores();
    let workers = clevrtex_render::pool::default_workers();
    println!(
        "machine: {cores} core(s); `generate` defaults to {workers} worker(s) x {} Cycles thread(s)",
        (cores / workers).max(1)
    );
    if !(args.timeout > 0.0 && args.timeout.is_finite()) {
        anyhow::bail!(
            "`--timeout {}` must be a positive number of seconds\nhint: e.g. `--timeout 60`",
            args.timeout
        );
    }
    let deadline = Duration::from_secs_f64(args.timeout);
    let path = blender::locate(args.blender.as_deref())?;
    println!("blender: {}", path.display());
    let line = blender::version_line_within(&path, deadline)?;
    let mut problems = Vec::new();
    match blender::parse_version(&line) {
        Some((major, minor, patch)) => {
            println!("version: {major}.{minor}.{patch}");
            if (major, minor) != TARGET {
                println!(
                    "  note: the bridge targets Blender {}.{}; other versions may differ in passes or looks",
                    TARGET.0, TARGET.1
                );
            }
        }
        None => problems.push(format!(
            "`{} --version` printed `{line}`, not a Blender version",
            path.display()
        )),
    }
    let materials = clevrtex_render::default_materials_json()
        .map_err(|e| anyhow::anyhow!("the built-in material catalogue is invalid: {e}"))?;
    let bridge = BridgeDir::create(&materials)?;
    println!(
        "bridge: {} embedded file(s), protocol version {}",
        clevrtex_render::bridge::files().len(),
        clevrtex_render::bridge::BRIDGE_VERSION
    );
    match Worker::start(&WorkerOptions {
        blender: path.clone(),
        script: bridge.worker_script(),
        materials: bridge.materials_json(),
        threads: 1,
        startup_timeout: deadline,
        interrupt: Arc::new(AtomicBool::new(false)),
        device: Default::default(),
    }) {
        Ok(worker) => {
            let ready = worker.ready().clone();
            println!(
                "worker: started in {:.1} s, reports Blender {}",
                worker.startup_time().as_secs_f64(),
                ready.blender_version
            );
            println!(
                "cycles devices: {}",
                if ready.cycles_devices.is_empty() {
                    "(none reported)".to_string()
                } else {
                    ready.cycles_devices.join(", ")
                }
            );
            if !ready.cycles_devices.iter().any(|d| d == "CPU") {
                problems.push("Cycles reports no CPU device".to_string());
            }
            worker.quit();
        }
        Err(e) => {
            // The worker error's own hint sends the user to `clevrtex doctor`: drop it here.
            let text = e.to_string();
            let text = match text.rfind("\nhint: ") {
                Some(i) => text[..i].to_string(),
                None => text,
            };
            problems.push(format!("the bridge does not start in this Blender: {text}"))
        }
    }
    if problems.is_empty() {
        println!("ok: everything `clevrtex generate` needs is here");
        Ok(exit::OK)
    } else {
        for p in &problems {
            println!("missing: {p}");
        }
        anyhow::bail!(
            "{} problem(s) found\nhint: install Debian's Blender with `apt-get install blender`, or pass another with `--blender PATH`",
            problems.len()
        )
    }
}
