//! `clevrtex doctor`: what Blender is found, its version, its Cycles devices, whether the
//! embedded bridge starts in it, and what is missing.

use std::path::PathBuf;
use std::time::Duration;

use clevrtex_render::{blender, doctor};

use crate::exit::{self, CmdResult};

/// The Blender versions the bridge supports (`blender_scripts/compat.py`), inclusive.
const SUPPORTED: [(u32, u32); 2] = [(3, 4), (5, 0)];

/// Arguments of `clevrtex doctor`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// Blender to check: an executable or a Python with `bpy` (default: `blender` on PATH,
    /// else `./.venv-bpy/bin/python`).
    #[arg(long, env = "CLEVRTEX_BLENDER", value_name = "PATH")]
    blender: Option<PathBuf>,
    /// Seconds each check may take (`blender --version`, the bridge's start-up) before the
    /// program is killed and reported.
    /// More than 0, at most 604800 (a week).
    #[arg(long, default_value_t = 60.0, value_name = "SECS")]
    timeout: f64,
}

/// Run `clevrtex doctor`.
pub fn run(args: Args) -> CmdResult {
    println!("clevrtex {}", crate::provenance::VERSION_LINE);
    let cores = clevrtex_render::pool::available_cores();
    let workers = clevrtex_render::pool::default_workers();
    println!(
        "machine: {cores} core(s); `generate` defaults to {workers} worker(s) x {} Cycles thread(s)",
        (cores / workers).max(1)
    );
    let deadline = crate::run_args::seconds("--timeout", args.timeout)?;
    let path = blender::locate(args.blender.as_deref())?;
    println!("blender: {}", path.display());
    let line = blender::version_line_within(&path, deadline)?;
    let mut problems = Vec::new();
    match blender::parse_version(&line) {
        Some((major, minor, patch)) => {
            println!("version: {major}.{minor}.{patch}");
            if (major, minor) < SUPPORTED[0] || (major, minor) > SUPPORTED[1] {
                println!(
                    "  note: the bridge supports Blender {}.{} to {}.{}; other versions may differ in passes or looks",
                    SUPPORTED[0].0, SUPPORTED[0].1, SUPPORTED[1].0, SUPPORTED[1].1
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
    println!(
        "bridge: {} embedded file(s), protocol version {}",
        clevrtex_render::bridge::files().len(),
        clevrtex_render::bridge::BRIDGE_VERSION
    );
    match doctor::probe(&path, &materials, deadline) {
        Ok(probe) => {
            let ready = probe.ready;
            println!(
                "worker: started in {:.1} s, reports Blender {}",
                probe.startup_s, ready.blender_version
            );
            println!(
                "cycles devices: {}",
                if ready.cycles_devices.is_empty() {
                    "(none reported)".to_string()
                } else {
                    ready.cycles_devices.join(", ")
                }
            );
            println!("{}", ready.features_line());
            let caps = clevrtex_render::device::nvidia_compute_capabilities();
            ready
                .cuda_kernel_lines(&caps)
                .iter()
                .for_each(|l| println!("{l}"));
            if !ready.cycles_devices.iter().any(|d| d == "CPU") {
                problems.push("Cycles reports no CPU device".to_string());
            }
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
    list_blenders(&path, args.blender.is_some(), deadline);
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

/// One line per Blender found (PATH, `CLEVRTEX_BLENDER`, `./.venv-bpy`): its kind, version,
/// Cycles devices and features, and which one `generate` uses. Probed in parallel; a
/// Blender that does not start is listed with why, and is not a problem of this check.
fn list_blenders(checked: &std::path::Path, explicit: bool, deadline: Duration) {
    let used = if explicit {
        Some(checked.to_path_buf())
    } else {
        blender::locate(None).ok()
    };
    let found = doctor::probe_all(used.as_deref(), deadline);
    println!("blenders found (* = the one `generate` uses; pick another with `--blender PATH`):");
    if found.is_empty() {
        println!("    (none on PATH, in CLEVRTEX_BLENDER or ./.venv-bpy)");
    }
    for f in found {
        let version = f.version.unwrap_or_else(|e| format!("no version ({e})"));
        let detail = match f.probe {
            Ok(ready) => format!(
                "cycles devices: {}; {}",
                ready.cycles_devices.join(", "),
                ready.features_line()
            ),
            Err(e) => format!("the bridge does not start: {e}"),
        };
        println!(
            "{}{} [{}]: {version} ({})\n      {detail}",
            if f.used { "  * " } else { "    " },
            f.path.display(),
            f.from,
            f.flavour.describe()
        );
    }
}
