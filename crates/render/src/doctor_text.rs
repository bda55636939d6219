//! What `clevrtex doctor` prints of what it found, as text (the command prints each part as
//! soon as its check ends): a Blender's version ([`version_lines`]), its worker's probe
//! ([`probe_lines`]) and every Blender found ([`found_text`]); problems go to the caller's list.

use std::fmt::Write;

use crate::doctor::{Found, Probe};
use crate::error::Result;

/// The Blender versions the bridge supports (`blender_scripts/compat.py`), inclusive.
pub const SUPPORTED: [(u32, u32); 2] = [(3, 4), (5, 0)];

/// `blender --version`'s first line `line` of `path`: the version (and a note when the bridge
/// does not support it), or a problem.
pub fn version_lines(path: &std::path::Path, line: &str, problems: &mut Vec<String>) -> String {
    match crate::blender::parse_version(line) {
        Some((major, minor, patch)) => {
            let mut out = format!("version: {major}.{minor}.{patch}\n");
            if (major, minor) < SUPPORTED[0] || (major, minor) > SUPPORTED[1] {
                let _ = writeln!(
                    out,
                    "  note: the bridge supports Blender {}.{} to {}.{}; other versions may differ in passes or looks",
                    SUPPORTED[0].0, SUPPORTED[0].1, SUPPORTED[1].0, SUPPORTED[1].1
                );
            }
            out
        }
        None => {
            problems.push(format!(
                "`{} --version` printed `{line}`, not a Blender version",
                path.display()
            ));
            String::new()
        }
    }
}

/// The worker's start, devices, features and CUDA kernels (`caps`: the GPUs' compute
/// capabilities), or the problem that it did not start.
pub fn probe_lines(
    probe: Result<Probe>,
    caps: &[(String, u32)],
    problems: &mut Vec<String>,
) -> String {
    let mut lines = Vec::new();
    match probe {
        Ok(probe) => {
            let ready = probe.ready;
            let devices = if ready.cycles_devices.is_empty() {
                "(none reported)".to_string()
            } else {
                ready.cycles_devices.join(", ")
            };
            lines.push(format!(
                "worker: started in {:.1} s, reports Blender {}",
                probe.startup_s, ready.blender_version
            ));
            lines.push(format!("cycles devices: {devices}"));
            lines.push(ready.features_line());
            lines.extend(ready.cuda_kernel_lines(caps));
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
    lines.iter().map(|l| format!("{l}\n")).collect()
}

/// One line per Blender found: its kind, version, Cycles devices and features, and which one
/// `generate` uses; a Blender that does not start is listed with why.
pub fn found_text(found: Vec<Found>) -> String {
    let mut out = String::from(
        "blenders found (* = the one `generate` uses; pick another with `--blender PATH`):\n",
    );
    if found.is_empty() {
        out.push_str("    (none on PATH, in CLEVRTEX_BLENDER or ./.venv-bpy)\n");
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
        let _ = writeln!(
            out,
            "{}{} [{}]: {version} ({})\n      {detail}",
            if f.used { "  * " } else { "    " },
            f.path.display(),
            f.from,
            f.flavour.describe()
        );
    }
    out
}
