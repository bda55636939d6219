//! `clevrtex doctor`: what Blender is found, its version, its Cycles devices, whether the
//! embedded bridge starts in it, and what is missing.

use std::path::PathBuf;

use clevrtex_render::{blender, doctor, doctor_text};

use crate::exit::{self, CmdResult};

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
    print!(
        "{}",
        doctor_text::version_lines(&path, &line, &mut problems)
    );
    let materials = clevrtex_render::default_materials_json()
        .map_err(|e| anyhow::anyhow!("the built-in material catalogue is invalid: {e}"))?;
    println!(
        "bridge: {} embedded file(s), protocol version {}",
        clevrtex_render::bridge::files().len(),
        clevrtex_render::bridge::BRIDGE_VERSION
    );
    let probe = doctor::probe(&path, &materials, deadline);
    let caps = match probe {
        Ok(_) => clevrtex_render::device::nvidia_compute_capabilities(),
        Err(_) => Vec::new(),
    };
    print!("{}", doctor_text::probe_lines(probe, &caps, &mut problems));
    // Every Blender found (PATH, `CLEVRTEX_BLENDER`, `./.venv-bpy`), probed in parallel; one
    // that does not start is not a problem of this check.
    let used = if args.blender.is_some() {
        Some(path.clone())
    } else {
        blender::locate(None).ok()
    };
    print!(
        "{}",
        doctor_text::found_text(doctor::probe_all(used.as_deref(), deadline))
    );
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
