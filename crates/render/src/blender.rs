//! Finding Blender and asking its version.

use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::{Duration, Instant};

use crate::error::{RenderError, Result};

/// Environment variable naming the Blender executable (used when `--blender` is not given).
pub const BLENDER_ENV: &str = "CLEVRTEX_BLENDER";

/// Find Blender: `explicit` if given (it must exist), else `$CLEVRTEX_BLENDER`, else
/// `blender` on `PATH`.
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
        } else {
            Err(RenderError::BlenderNotFound { tried: Some(path) })
        };
    }
    find_on_path("blender").ok_or(RenderError::BlenderNotFound { tried: None })
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

/// The first line of `blender --version` (e.g. `Blender 3.4.1`), within `timeout`.
pub fn version_line_within(blender: &Path, timeout: Duration) -> Result<String> {
    let mut child = Command::new(blender)
        .arg("--version")
        .stdin(std::process::Stdio::null())
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::null())
        .spawn()
        .map_err(|source| RenderError::Spawn {
            program: blender.to_path_buf(),
            cause: source,
        })?;
    let mut stdout = child.stdout.take().expect("piped");
    let reader = std::thread::spawn(move || {
        let mut s = String::new();
        let _ = std::io::Read::read_to_string(&mut stdout, &mut s);
        s
    });
    let deadline = Instant::now() + timeout;
    loop {
        match child.try_wait() {
            Ok(Some(_)) => break,
            Ok(None) if Instant::now() < deadline => std::thread::sleep(Duration::from_millis(20)),
            _ => {
                let _ = child.kill();
                let _ = child.wait();
                return Err(RenderError::VersionTimeout {
                    program: blender.to_path_buf(),
                    waited: timeout,
                });
            }
        }
    }
    let text = reader.join().unwrap_or_default();
    Ok(text
        .lines()
        .map(str::trim)
        .find(|l| l.starts_with("Blender"))
        .unwrap_or_else(|| text.lines().next().unwrap_or(""))
        .to_string())
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
