//! Finding Blender, telling a Blender executable from a Python that imports `bpy`, and
//! asking its version.
//!
//! `--blender PATH` (or `CLEVRTEX_BLENDER`) names either a Blender executable (Debian's
//! `blender`, an official build) or a Python interpreter that can `import bpy` (a venv with
//! PyPI's `bpy` wheel, e.g. `.venv-bpy/bin/python` from `scripts/setup.sh --bpy 4.5`). Which
//! one it is ([`Flavour`]) decides how the worker is started: see [`worker_command`].

use std::collections::HashMap;
use std::path::{Path, PathBuf};
use std::process::Command;
use std::sync::{Mutex, OnceLock};
use std::time::{Duration, Instant};

use crate::error::{RenderError, Result};

/// Environment variable naming the Blender executable (used when `--blender` is not given).
pub const BLENDER_ENV: &str = "CLEVRTEX_BLENDER";

/// The project's bpy venv (`scripts/setup.sh --bpy 4.5`), relative to the working folder.
pub const PROJECT_VENV_PYTHON: &str = ".venv-bpy/bin/python";

/// What kind of program `--blender` names.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Flavour {
    /// A Blender executable: `blender -b --factory-startup --python worker.py -- ARGS`.
    Executable,
    /// A Python interpreter with the `bpy` module: `python worker.py -- ARGS --factory-startup`
    /// (the module has no command line, so the bridge resets to factory settings itself).
    PythonModule,
}

impl Flavour {
    /// `blender` or `bpy module`, for messages.
    pub fn describe(self) -> &'static str {
        match self {
            Flavour::Executable => "blender executable",
            Flavour::PythonModule => "python with bpy",
        }
    }
}

/// How a [`Flavour`] is decided from the file name alone: `python*` is a Python, `blender*` a
/// Blender; `None` for anything else (then the program is asked, see [`flavour`]).
pub fn flavour_from_name(path: &Path) -> Option<Flavour> {
    let name = path.file_name()?.to_string_lossy().to_ascii_lowercase();
    if name.starts_with("python") {
        Some(Flavour::PythonModule)
    } else if name.starts_with("blender") {
        Some(Flavour::Executable)
    } else {
        None
    }
}

/// How a [`Flavour`] is decided from the first line `PROGRAM --version` prints: Python prints
/// `Python 3.11.2`, Blender `Blender 3.4.1`.
pub fn flavour_from_version_output(text: &str) -> Flavour {
    if text
        .lines()
        .map(str::trim)
        .any(|l| l.starts_with("Python "))
        && !text.lines().any(|l| l.trim().starts_with("Blender"))
    {
        Flavour::PythonModule
    } else {
        Flavour::Executable
    }
}

fn flavour_cache() -> &'static Mutex<HashMap<PathBuf, Flavour>> {
    static CACHE: OnceLock<Mutex<HashMap<PathBuf, Flavour>>> = OnceLock::new();
    CACHE.get_or_init(|| Mutex::new(HashMap::new()))
}

/// Whether `program` is a Blender executable or a Python with `bpy`: by its file name when
/// that says (`python3`, `blender-4.5`), else by running `PROGRAM --version` once (cached per
/// path for the life of the process). A program that does not answer counts as Blender, so
/// its start-up failure is reported by the worker with Blender's output.
pub fn flavour(program: &Path) -> Flavour {
    if let Some(f) = flavour_from_name(program) {
        return f;
    }
    if let Some(f) = flavour_cache().lock().unwrap().get(program) {
        return *f;
    }
    let f = run_capturing(program, &["--version"], Duration::from_secs(10))
        .map(|text| flavour_from_version_output(&text))
        .unwrap_or(Flavour::Executable);
    flavour_cache()
        .lock()
        .unwrap()
        .insert(program.to_path_buf(), f);
    f
}

/// The program and arguments that start the bridge's `script` in `program` of `flavour`,
/// followed by the bridge's own arguments `bridge_args`.
pub fn worker_command(
    program: &Path,
    flavour: Flavour,
    script: &Path,
    bridge_args: &[std::ffi::OsString],
) -> Command {
    let mut cmd = Command::new(program);
    match flavour {
        Flavour::Executable => {
            cmd.args([
                "-b",
                "--factory-startup",
                "--python-exit-code",
                "1",
                "--python",
            ])
            .arg(script)
            .arg("--")
            .args(bridge_args);
        }
        Flavour::PythonModule => {
            // `-u`: unbuffered (the bridge writes replies with write(2) anyway); `-s`: no
            // user site-packages, so only the venv's bpy is seen; `-B`: no .pyc next to the
            // bridge's temporary copy.
            cmd.args(["-u", "-s", "-B"])
                .arg(script)
                .arg("--")
                .args(bridge_args)
                .arg("--factory-startup");
        }
    }
    cmd
}

/// Find Blender: `explicit` if given (it must exist), else `$CLEVRTEX_BLENDER`, else
/// `blender` on `PATH`, else the project venv's `./.venv-bpy/bin/python`. Each may be a
/// Blender executable or a Python with `bpy` ([`flavour`]).
pub fn locate(explicit: Option<&Path>) -> Result<PathBuf> {
    let given = explicit.map(Path::to_path_buf).or_else(|| {
        std::env::var_os(BLENDER_ENV)
            .filter(|v| !v.is_empty())
            .map(PathBuf::from)
    });
    if let Some(path) = given {
        if path.components().count() == 1 && !path.exists() {
            // A bare name such as `blender-4.2`: look it up on PATH.
            return find_on_path(&path.to_string_lossy())
                .ok_or(RenderError::BlenderNotFound { tried: Some(path) });
        }
        return if path.is_file() {
            Ok(path)
        } else if path.is_dir() {
            Err(RenderError::BlenderIsFolder { path })
        } else {
            Err(RenderError::BlenderNotFound { tried: Some(path) })
        };
    }
    find_on_path("blender")
        .or_else(|| Some(PathBuf::from(PROJECT_VENV_PYTHON)).filter(|p| p.is_file()))
        .ok_or(RenderError::BlenderNotFound { tried: None })
}

/// Every Blender this machine offers, for `clevrtex doctor`: `blender` on `PATH`,
/// `$CLEVRTEX_BLENDER`, and the project venv's Python (`./.venv-bpy/bin/python`), each once
/// (by canonical path), with where it was found.
pub fn candidates() -> Vec<(PathBuf, &'static str)> {
    let mut out: Vec<(PathBuf, &'static str)> = Vec::new();
    let mut push = |p: PathBuf, from: &'static str| {
        let key = std::fs::canonicalize(&p).unwrap_or_else(|_| p.clone());
        if p.is_file()
            && !out
                .iter()
                .any(|(q, _)| std::fs::canonicalize(q).unwrap_or_else(|_| q.clone()) == key)
        {
            out.push((p, from));
        }
    };
    if let Some(p) = std::env::var_os(BLENDER_ENV).filter(|v| !v.is_empty()) {
        let p = PathBuf::from(p);
        let p = if p.components().count() == 1 && !p.exists() {
            find_on_path(&p.to_string_lossy()).unwrap_or(p)
        } else {
            p
        };
        push(p, BLENDER_ENV);
    }
    if let Some(p) = find_on_path("blender") {
        push(p, "PATH");
    }
    push(PathBuf::from(PROJECT_VENV_PYTHON), "./.venv-bpy");
    out
}

fn find_on_path(name: &str) -> Option<PathBuf> {
    let path = std::env::var_os("PATH")?;
    std::env::split_paths(&path)
        .map(|dir| dir.join(name))
        .find(|p| p.is_file())
}

/// How long `blender --version` may take (it takes ~1 s; a Blender that never answers is
/// killed and reported instead of hanging the command).
pub const VERSION_TIMEOUT: Duration = Duration::from_secs(30);

/// The first line of `blender --version` (e.g. `Blender 3.4.1`), within `timeout`. For a
/// Python with `bpy` the same line is made by importing it (`Blender 4.5.3 LTS`); a Python
/// without `bpy` yields its import error's last line.
pub fn version_line_within(blender: &Path, timeout: Duration) -> Result<String> {
    let text = match flavour(blender) {
        Flavour::Executable => run_capturing(blender, &["--version"], timeout)?,
        Flavour::PythonModule => run_capturing(
            blender,
            &[
                "-s",
                "-c",
                "import sys\ntry:\n import bpy\nexcept Exception as e:\n print('no bpy: %s' % e); sys.exit(0)\nprint('Blender', bpy.app.version_string)",
            ],
            timeout,
        )?,
    };
    Ok(text
        .lines()
        .map(str::trim)
        .find(|l| l.starts_with("Blender") || l.starts_with("no bpy"))
        .unwrap_or_else(|| text.lines().next().unwrap_or(""))
        .to_string())
}

/// Most of a `--version` probe's stdout that is kept (Blender prints a few hundred bytes);
/// the rest is read and dropped, so a program that prints without end costs no memory.
const MAX_PROBE_OUTPUT: u64 = 64 * 1024;

/// Run `program args` with no stdin, returning the first [`MAX_PROBE_OUTPUT`] bytes of its
/// stdout (stderr dropped) once it exits, or [`RenderError::VersionTimeout`] after `timeout`
/// (it is killed, with its process group: a wrapper script's children too).
fn run_capturing(program: &Path, args: &[&str], timeout: Duration) -> Result<String> {
    let blender = program;
    let mut cmd = Command::new(blender);
    cmd.args(args)
        .stdin(std::process::Stdio::null())
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::null());
    crate::group::own_group(&mut cmd);
    let mut child = cmd.spawn().map_err(|source| RenderError::Spawn {
        program: blender.to_path_buf(),
        cause: source,
    })?;
    crate::group::track(&child);
    let stdout = child.stdout.take().expect("piped");
    let reader = std::thread::spawn(move || {
        let mut kept = Vec::new();
        let mut stdout = stdout;
        let _ = std::io::Read::read_to_end(
            &mut std::io::Read::take(&mut stdout, MAX_PROBE_OUTPUT),
            &mut kept,
        );
        // Drain the rest without keeping it, so the program is not blocked on a full pipe.
        let _ = std::io::copy(&mut stdout, &mut std::io::sink());
        String::from_utf8_lossy(&kept).into_owned()
    });
    let deadline = Instant::now() + timeout;
    loop {
        match child.try_wait() {
            Ok(Some(_)) => break,
            Ok(None) if Instant::now() < deadline => std::thread::sleep(Duration::from_millis(20)),
            _ => {
                crate::group::kill_group(&mut child);
                return Err(RenderError::VersionTimeout {
                    program: blender.to_path_buf(),
                    waited: timeout,
                });
            }
        }
    }
    // A wrapper may have exited leaving a child that holds the pipe open: stop the group.
    crate::group::kill_group(&mut child);
    Ok(reader.join().unwrap_or_default())
}

/// [`version_line_within`] the default [`VERSION_TIMEOUT`].
pub fn version_line(blender: &Path) -> Result<String> {
    version_line_within(blender, VERSION_TIMEOUT)
}

/// The version numbers in a `Blender X.Y.Z` line.
pub fn parse_version(line: &str) -> Option<(u32, u32, u32)> {
    let v = line.split_whitespace().nth(1)?;
    let mut it = v.split('.').map(|p| p.parse::<u32>().ok());
    Some((it.next()??, it.next()??, it.next().flatten().unwrap_or(0)))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parses_versions() {
        assert_eq!(parse_version("Blender 3.4.1"), Some((3, 4, 1)));
        assert_eq!(parse_version("Blender 4.2"), Some((4, 2, 0)));
        assert_eq!(parse_version("nonsense"), None);
    }

    #[test]
    fn missing_explicit_path_is_named() {
        let err = locate(Some(Path::new("/no/such/blender"))).unwrap_err();
        let msg = err.to_string();
        assert!(msg.contains("`/no/such/blender`"), "{msg}");
        assert!(msg.contains("apt-get install blender"), "{msg}");
        assert!(msg.contains("--blender"), "{msg}");
    }
}
