//! Runs `blender_scripts/material_tool.py` in one Blender process for a batch of materials:
//! the renders behind the contact sheet, the build check, the distinctness statistics and
//! the cost measurement.

use std::io::{BufRead, BufReader, Read};
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};

use serde_json::Value;

use crate::Catalogue;

/// The bridge scripts the tool needs, embedded so an installed binary never hunts for them.
pub const SCRIPTS: &[(&str, &str)] = &[
    (
        "materials.py",
        include_str!("../../../blender_scripts/materials.py"),
    ),
    (
        "material_nodes.py",
        include_str!("../../../blender_scripts/material_nodes.py"),
    ),
    (
        "material_blocks.py",
        include_str!("../../../blender_scripts/material_blocks.py"),
    ),
    (
        "material_tool.py",
        include_str!("../../../blender_scripts/material_tool.py"),
    ),
];

/// What to render for each material.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Mode {
    /// A sphere and a cube on a grey floor, labelled (the contact sheet).
    Sheet,
    /// A flat-lit square seen straight down (distinctness statistics).
    Tile,
    /// Like `Sheet`, plus a count of pink (missing-texture) pixels.
    Check,
    /// A sphere filling the frame, timed.
    Cost,
    /// A small and a large cube side by side, orthographic (density invariance).
    Density,
}

impl Mode {
    fn name(self) -> &'static str {
        match self {
            Mode::Sheet => "sheet",
            Mode::Tile => "tile",
            Mode::Check => "check",
            Mode::Cost => "cost",
            Mode::Density => "density",
        }
    }
}

/// One batch.
#[derive(Debug, Clone)]
pub struct ToolRun {
    /// The Blender executable.
    pub blender: PathBuf,
    /// What to render.
    pub mode: Mode,
    /// Image width in pixels.
    pub size: u32,
    /// Samples per pixel.
    pub samples: u32,
    /// Cycles threads (0: automatic).
    pub threads: u32,
    /// Where `<name>.png` files go.
    pub out_dir: PathBuf,
    /// Displacement strength given to every instance (0: none).
    pub displacement: f64,
    /// The instance `random` value (0.37 unless comparing instances).
    pub random: f64,
}

/// The reply for one material.
#[derive(Debug, Clone)]
pub struct Reply {
    /// Material name.
    pub name: String,
    /// The JSON reply: `ok`, `render_s`, `file`, `pink`, or `error` and `traceback`.
    pub value: Value,
}

/// A failed Blender run: program, status and the tails of its output.
#[derive(Debug, thiserror::Error)]
#[error("blender run failed: `{program}` exited with {status}\n--- stdout (tail)\n{stdout}\n--- stderr (tail)\n{stderr}\nhint: run `clevrtex doctor` to check the Blender installation")]
pub struct ToolError {
    /// The program.
    pub program: String,
    /// Exit status, as text.
    pub status: String,
    /// Last lines of stdout.
    pub stdout: String,
    /// Last lines of stderr.
    pub stderr: String,
}

/// The Blender to use: `CLEVRTEX_BLENDER`, else `blender` on `PATH`.
pub fn find_blender() -> Option<PathBuf> {
    if let Some(p) = std::env::var_os("CLEVRTEX_BLENDER") {
        return Some(PathBuf::from(p));
    }
    let path = std::env::var_os("PATH")?;
    std::env::split_paths(&path)
        .map(|d| d.join("blender"))
        .find(|p| p.is_file())
}

impl ToolRun {
    /// Render `names` (all from `cat`) in one Blender process; one reply per name.
    pub fn run(&self, cat: &Catalogue, names: &[&str]) -> Result<Vec<Reply>, ToolError> {
        let io_err = |e: std::io::Error| ToolError {
            program: self.blender.display().to_string(),
            status: "not started".into(),
            stdout: String::new(),
            stderr: e.to_string(),
        };
        std::fs::create_dir_all(&self.out_dir).map_err(io_err)?;
        let work = self.out_dir.join(".tool");
        std::fs::create_dir_all(&work).map_err(io_err)?;
        for (name, text) in SCRIPTS {
            std::fs::write(work.join(name), text).map_err(io_err)?;
        }
        let mjson = work.join("materials.json");
        std::fs::write(&mjson, cat.resolved_json_for(names.iter().copied())).map_err(io_err)?;
        let tag = format!("@@clevrtex-mat-{}@@", std::process::id());
        let mut child = Command::new(&self.blender)
            .args([
                "-b",
                "--factory-startup",
                "--python-exit-code",
                "1",
                "--python",
            ])
            .arg(work.join("material_tool.py"))
            .arg("--")
            .args(["--mode", self.mode.name(), "--materials"])
            .arg(&mjson)
            .arg("--names")
            .arg(names.join(","))
            .arg("--out-dir")
            .arg(&self.out_dir)
            .args(["--size", &self.size.to_string()])
            .args(["--samples", &self.samples.to_string()])
            .args(["--threads", &self.threads.to_string()])
            .args(["--displacement", &self.displacement.to_string()])
            .args(["--random", &self.random.to_string()])
            .args(["--tag", &tag])
            .stdin(Stdio::null())
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()
            .map_err(io_err)?;
        let mut stderr = child.stderr.take().expect("piped");
        let err_thread = std::thread::spawn(move || {
            let mut s = String::new();
            let _ = stderr.read_to_string(&mut s);
            s
        });
        let mut replies = Vec::new();
        let mut tail: Vec<String> = Vec::new();
        let stdout = child.stdout.take().expect("piped");
        for line in BufReader::new(stdout).lines() {
            let Ok(line) = line else { break };
            if let Some(rest) = line.strip_prefix(&tag).map(str::trim) {
                if let Ok(v) = serde_json::from_str::<Value>(rest) {
                    let name = v["name"].as_str().unwrap_or("").to_string();
                    replies.push(Reply { name, value: v });
                    continue;
                }
            }
            tail.push(line);
            if tail.len() > 40 {
                tail.remove(0);
            }
        }
        let status = child.wait().map_err(io_err)?;
        let err_text = err_thread.join().unwrap_or_default();
        if !status.success() || replies.len() != names.len() {
            let err_tail: Vec<&str> = err_text.lines().collect();
            let from = err_tail.len().saturating_sub(40);
            return Err(ToolError {
                program: self.blender.display().to_string(),
                status: status.to_string(),
                stdout: tail.join("\n"),
                stderr: err_tail[from..].join("\n"),
            });
        }
        Ok(replies)
    }
}

/// Whether `path` exists and is a file (for cache checks).
pub fn cached(path: &Path) -> bool {
    path.is_file()
}
