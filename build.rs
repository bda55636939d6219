//! Records the git commit the `clevrtex` binary is built from, for `--version`, `doctor`, the
//! run manifests and the dataset card (docs/runs.md, "Provenance").
//!
//! Sets `CLEVRTEX_COMMIT` (40 hex digits, or `unknown`), `CLEVRTEX_TREE_MODIFIED` (`true`,
//! `false` or `unknown`: whether a tracked source file differed from that commit) and
//! `CLEVRTEX_VERSION_LINE` (`0.1.0 (commit 0123456789ab, modified)`). Not built from a git
//! checkout (a source tarball, a container build without `.git`), the packager may set
//! `CLEVRTEX_BUILD_COMMIT` to the commit (a `-modified` suffix marks a changed tree); without
//! it both are `unknown`.
//!
//! Cargo reruns this script only when the commit or a source can have changed: `HEAD`, the
//! branch's ref (or `packed-refs`) and the folders compiled into the binary, each only if it
//! exists (a missing path would rerun it on every build). The git index is not watched, as
//! `git status` elsewhere rewrites it.

use std::path::{Path, PathBuf};
use std::process::Command;

/// What the binary is built from; `modified` is judged on these paths only (the Python
/// package, docs and tests are not compiled into it).
const SOURCES: &[&str] = &[
    "build.rs",
    "Cargo.toml",
    "Cargo.lock",
    "blender_scripts",
    "configs",
    "materials",
    "crates/core",
    "crates/scene",
    "crates/dataset",
    "crates/render",
    "crates/eval",
    "crates/materials",
    "crates/bench",
    "crates/report",
    "crates/build",
];

fn git(dir: &Path, args: &[&str]) -> Option<(bool, String)> {
    let o = Command::new("git")
        .arg("-C")
        .arg(dir)
        .args(args)
        .output()
        .ok()?;
    let text = String::from_utf8(o.stdout).ok()?.trim().to_string();
    Some((o.status.success(), text))
}

fn watch(path: &Path) {
    if path.exists() {
        println!("cargo:rerun-if-changed={}", path.display());
    }
}

fn main() {
    let dir = PathBuf::from(std::env::var("CARGO_MANIFEST_DIR").expect("cargo sets it"));
    println!("cargo:rerun-if-env-changed=CLEVRTEX_BUILD_COMMIT");
    for s in SOURCES {
        watch(&dir.join(s));
    }
    let (commit, modified) =
        from_git(&dir).unwrap_or_else(|| match std::env::var("CLEVRTEX_BUILD_COMMIT") {
            Ok(c) if !c.trim().is_empty() => {
                let c = c.trim();
                match c.strip_suffix("-modified") {
                    Some(c) => (c.to_string(), "true".to_string()),
                    None => (c.to_string(), "false".to_string()),
                }
            }
            _ => ("unknown".to_string(), "unknown".to_string()),
        });
    let short: String = commit.chars().take(12).collect();
    let line = match modified.as_str() {
        "true" => format!("commit {short}, modified"),
        _ => format!("commit {short}"),
    };
    println!("cargo:rustc-env=CLEVRTEX_COMMIT={commit}");
    println!("cargo:rustc-env=CLEVRTEX_TREE_MODIFIED={modified}");
    println!(
        "cargo:rustc-env=CLEVRTEX_VERSION_LINE={} ({line})",
        std::env::var("CARGO_PKG_VERSION").expect("cargo sets it")
    );
}

/// The commit of `HEAD` and whether a tracked source differs from it; `None` outside a git
/// checkout (or without `git`).
fn from_git(dir: &Path) -> Option<(String, String)> {
    let (ok, commit) = git(dir, &["rev-parse", "--verify", "-q", "HEAD"])?;
    if !ok || commit.len() != 40 || !commit.chars().all(|c| c.is_ascii_hexdigit()) {
        return None;
    }
    // `HEAD` moves on checkout and detach; the branch's ref on commit (loose or packed).
    let path = |p: &str| git(dir, &["rev-parse", "--git-path", p]).map(|(_, t)| dir.join(t));
    if let Some(p) = path("HEAD") {
        watch(&p);
    }
    if let Some((true, branch)) = git(dir, &["symbolic-ref", "-q", "HEAD"]) {
        if let Some(p) = path(&branch) {
            watch(&p);
        }
    }
    if let Some(p) = path("packed-refs") {
        watch(&p);
    }
    // Exit status 1: a tracked source differs from the commit (staged or not).
    let mut args = vec!["diff", "--no-ext-diff", "--quiet", "HEAD", "--"];
    args.extend(SOURCES);
    let modified = match Command::new("git")
        .arg("-C")
        .arg(dir)
        .args(&args)
        .status()
        .ok()
        .and_then(|s| s.code())
    {
        Some(0) => "false",
        Some(1) => "true",
        _ => "unknown",
    };
    Some((commit, modified.to_string()))
}
