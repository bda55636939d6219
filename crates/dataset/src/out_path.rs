//! The one check of an output path given on the command line (`preview --out`, `report
//! --out`, `export OUT`, `eval --json/--csv`, `verify --json`, `materials sheet --out`): the
//! path is resolved as the file system will resolve it once its missing folders are made
//! ([`resolve`]: links followed, `..` taken after them, missing parts included), before
//! anything is created, and refused inside a dataset (or other folder) the command reads
//! ([`check`]). Without the resolution `MISSING/../D/clevrtex_full/0/x.png` was judged by its
//! text and let through, and overwrote a sample of `D`.

use std::ffi::OsString;
use std::path::{Component, Path, PathBuf};

/// Links followed while resolving one path before it is refused as a loop (Linux's bound).
const MAX_LINKS: usize = 40;

/// `path` made absolute and resolved part by part as the kernel will once the missing
/// folders on the way are made (`create_dir_all`): a link is replaced by its target (read,
/// even when dangling), `..` goes up from what the part before it resolved to (so after a
/// link, from the link's target), a missing part stays as named. `Err`: a link loop, or the
/// working folder unknown.
pub fn resolve(path: &Path) -> Result<PathBuf, String> {
    let abs = if path.is_absolute() {
        path.to_path_buf()
    } else {
        std::env::current_dir()
            .map_err(|e| format!("cannot resolve `{}`: {e}", path.display()))?
            .join(path)
    };
    // Parts still to resolve, first last (a link's target is pushed in front of the rest).
    let mut todo: Vec<OsString> = Vec::new();
    push_parts(&mut todo, &abs);
    let mut done = PathBuf::from("/");
    let mut links = 0;
    while let Some(part) = todo.pop() {
        if part == "." || part.is_empty() {
            continue;
        }
        if part == ".." {
            done.pop();
            continue;
        }
        let next = done.join(&part);
        match std::fs::symlink_metadata(&next) {
            Ok(m) if m.file_type().is_symlink() => {
                links += 1;
                if links > MAX_LINKS {
                    return Err(format!(
                        "`{}` has more than {MAX_LINKS} links on the way (a loop?)",
                        path.display()
                    ));
                }
                let target = std::fs::read_link(&next)
                    .map_err(|e| format!("cannot read the link `{}`: {e}", next.display()))?;
                if target.is_absolute() {
                    done = PathBuf::from("/");
                }
                push_parts(&mut todo, &target);
            }
            _ => done = next,
        }
    }
    Ok(done)
}

/// Push the parts of `p` onto `todo` so the first part is popped first.
fn push_parts(todo: &mut Vec<OsString>, p: &Path) {
    for c in p.components().rev() {
        match c {
            Component::Normal(n) => todo.push(n.to_os_string()),
            Component::ParentDir => todo.push("..".into()),
            Component::CurDir | Component::RootDir | Component::Prefix(_) => {}
        }
    }
}

/// Check the output `out` of `flag` (e.g. `--out`) before anything is created: resolved
/// ([`resolve`]), it must not be inside (or be) any folder of `read`, the datasets (and other
/// inputs) the command reads, where it would overwrite or add files. The resolved path is
/// returned. The message names the flag, the path and the dataset, with a `hint:` line.
pub fn check(out: &Path, flag: &str, read: &[&Path]) -> Result<PathBuf, String> {
    let resolved = resolve(out)?;
    for dir in read {
        let Ok(root) = resolve(dir) else {
            continue;
        };
        if resolved.starts_with(&root) {
            let shown = clevrtex_scene::text::printable(&out.display().to_string()).into_owned();
            let through = if resolved.as_path() == out {
                String::new()
            } else {
                format!(" (it resolves to `{}`)", resolved.display())
            };
            return Err(format!(
                "`{flag} {shown}`{through} is inside the dataset `{}` (a folder this command reads): writing there would overwrite or add files of it\nhint: write the output outside that folder, e.g. `{flag} {}`",
                dir.display(),
                out.file_name()
                    .map(|n| n.to_string_lossy().into_owned())
                    .unwrap_or_else(|| "out".into())
            ));
        }
    }
    if let Some(dataset) = dataset_holding(&resolved) {
        let shown = clevrtex_scene::text::printable(&out.display().to_string()).into_owned();
        return Err(format!(
            "`{flag} {shown}` is inside the dataset `{}`: writing there would overwrite or add files of a dataset this command does not own\nhint: write the output outside that folder, e.g. `{flag} {}`",
            clevrtex_scene::text::printable(&dataset.display().to_string()),
            out.file_name()
                .map(|n| n.to_string_lossy().into_owned())
                .unwrap_or_else(|| "out".into())
        ));
    }
    Ok(resolved)
}

/// The dataset folder that holds the resolved path `p` (or is it), if any: the nearest folder
/// on its way that is a variant folder (`clevrtex_<name>` holding a run's `MANIFEST-*.json`
/// or a `SCENES-*.manifest`), or that holds one, or a suite's `SUITE.json`. Every command's
/// output is refused there, whether or not the command reads that dataset.
pub fn dataset_holding(p: &Path) -> Option<PathBuf> {
    let is_variant_dir = |d: &Path| {
        d.file_name()
            .and_then(|n| n.to_str())
            .is_some_and(|n| n.starts_with("clevrtex_"))
            && std::fs::read_dir(d).is_ok_and(|entries| {
                entries.flatten().any(|e| {
                    let name = e.file_name();
                    let name = name.to_string_lossy();
                    crate::manifest::is_manifest_name(&name)
                        || (name.starts_with("SCENES-") && name.ends_with(".manifest"))
                })
            })
    };
    for a in p.ancestors() {
        if !a.is_dir() {
            continue;
        }
        if is_variant_dir(a) {
            return Some(a.parent().unwrap_or(a).to_path_buf());
        }
        if a.join("SUITE.json").is_file() {
            return Some(a.to_path_buf());
        }
        let holds = std::fs::read_dir(a).is_ok_and(|entries| {
            entries
                .flatten()
                .any(|e| e.file_type().is_ok_and(|t| t.is_dir()) && is_variant_dir(&e.path()))
        });
        if holds {
            return Some(a.to_path_buf());
        }
    }
    None
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn missing_parts_dots_and_links_resolve_as_the_kernel_would() {
        let tmp = tempfile::tempdir().unwrap();
        let base = tmp.path().canonicalize().unwrap();
        let data = base.join("data");
        std::fs::create_dir_all(data.join("clevrtex_full/0")).unwrap();
        let target = data.join("clevrtex_full/0/CLEVRTEX_full_000000.png");
        // A missing folder followed by `..`: made first, then left.
        let sneaky = base.join("MISSING/../data/clevrtex_full/0/CLEVRTEX_full_000000.png");
        assert_eq!(resolve(&sneaky).unwrap(), target);
        // A link to inside the dataset, then `..` from the link's target.
        std::os::unix::fs::symlink(data.join("clevrtex_full/0"), base.join("l")).unwrap();
        assert_eq!(
            resolve(&base.join("l/../0/x.png")).unwrap(),
            data.join("clevrtex_full/0/x.png")
        );
        // A dangling link is followed to where it would create.
        std::os::unix::fs::symlink(data.join("new"), base.join("dangling")).unwrap();
        assert_eq!(
            resolve(&base.join("dangling/a.html")).unwrap(),
            data.join("new/a.html")
        );
        // A loop is an error, not a hang.
        std::os::unix::fs::symlink(base.join("loop"), base.join("loop")).unwrap();
        assert!(resolve(&base.join("loop/x")).unwrap_err().contains("links"));
        for out in [
            sneaky,
            base.join("l/x.png"),
            base.join("dangling/a.html"),
            data.clone(),
        ] {
            let e = check(&out, "--out", &[&data]).unwrap_err();
            assert!(e.contains("is inside") && e.contains("hint:"), "{e}");
        }
        assert!(check(&base.join("MISSING/x.png"), "--out", &[&data]).is_ok());
        assert!(check(&base.join("data2/x.png"), "--out", &[&data]).is_ok());
    }
}
