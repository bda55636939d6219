//! The published dataset layout (as the public loader `clevrtex_eval.py` of the public
//! generator, karazijal/clevrtex-generation, reads it), in one place: folders, stems, file names and
//! which split an index belongs to. Used by `sample`, `generate`/`render` and `eval`.
//!
//! `OUT/clevrtex_<variant>/<index / 1000>/CLEVRTEX_<variant>_<index:06>{.png, _flat.png,
//! _depth_0001.png, _normal_0001.png, _albedo_0001.png, _shadow_0001.png, .json}`; the pass
//! suffixes come from the pass table ([`clevrtex_scene::passes`]).

use std::path::{Path, PathBuf};

use clevrtex_scene::config::Config;
pub use clevrtex_scene::names::{
    pass_file, stem, variant_name_problem, Split, Splits, MAX_VARIANT_NAME,
};
use clevrtex_scene::passes::Pass;

/// Suffix of temporary files (never matched by the public loader's `*.png` glob).
pub const TMP_SUFFIX: &str = ".clevrtex-tmp";

/// Parse a file name `CLEVRTEX_<variant>_<index>` + `suffix` (the index at least six digits,
/// as [`stem`] writes it) into (stem, variant, index).
pub fn parse_stem<'a>(name: &'a str, suffix: &str) -> Option<(&'a str, &'a str, u64)> {
    let stem = name.strip_suffix(suffix)?;
    let rest = stem.strip_prefix("CLEVRTEX_")?;
    let (variant, digits) = rest.rsplit_once('_')?;
    if variant.is_empty() || digits.len() < 6 || !digits.bytes().all(|b| b.is_ascii_digit()) {
        return None;
    }
    Some((stem, variant, digits.parse().ok()?))
}

/// The stem, variant and index of a file of the layout: a pass (its suffix from the pass
/// table), the metadata or a kept EXR; `None` for any other name.
pub fn parse_file_name(name: &str) -> Option<(&str, &str, u64)> {
    let mut suffixes: Vec<String> = Pass::ALL.iter().map(|&p| pass_file("", p)).collect();
    suffixes.push(metadata_file(""));
    suffixes.extend(exr_files("", true));
    suffixes.sort_by_key(|s| std::cmp::Reverse(s.len()));
    suffixes.iter().find_map(|s| parse_stem(name, s))
}

/// The failure ledger's file name in a variant folder.
pub const LEDGER_FILE: &str = "failures.jsonl";

/// Folder of one variant: `OUT/clevrtex_<variant>`.
pub fn variant_dir(out: &Path, variant: &str) -> PathBuf {
    out.join(format!("clevrtex_{variant}"))
}

/// Folder of image `index`: `OUT/clevrtex_<variant>/<index / 1000>`.
pub fn sample_dir(out: &Path, variant: &str, index: u64) -> PathBuf {
    variant_dir(out, variant).join((index / 1000).to_string())
}

/// Make `dir`, a folder of the layout under `out` (a variant folder or a sample folder), and
/// every folder between, before anything is written into it. The one place the write side
/// makes the layout's folders: an `--out` handed over (to resume or grow it) is untrusted, so
/// every folder from `out` down to `dir` must be a folder inside `out`, judged as the read
/// side judges ([`crate::dataset::files::classify`] against the canonical `out`). A link leading out
/// of `out`, a dangling link, a FIFO or a file where a folder belongs is refused, naming it,
/// and nothing is written through it. `out` itself (the command line's) is trusted.
pub fn make_dir(out: &Path, dir: &Path) -> Result<(), String> {
    let hint = "hint: remove it (or put the real folder in its place), or pass another `--out`";
    std::fs::create_dir_all(out).map_err(|e| {
        format!(
            "cannot create `{}`: {e}\nhint: pass a writable folder with `--out`",
            out.display()
        )
    })?;
    let root = crate::dataset::files::root(out)
        .map_err(|e| format!("cannot resolve `{}`: {e}", out.display()))?;
    let rel = dir.strip_prefix(out).map_err(|_| {
        format!(
            "`{}` is not under the output folder `{}`",
            dir.display(),
            out.display()
        )
    })?;
    let mut path = out.to_path_buf();
    for part in rel.components() {
        path.push(part);
        if let Err(e) = std::fs::symlink_metadata(&path) {
            if e.kind() != std::io::ErrorKind::NotFound {
                return Err(format!("cannot read `{}`: {e}", path.display()));
            }
            match std::fs::create_dir(&path) {
                Err(e) if e.kind() != std::io::ErrorKind::AlreadyExists => {
                    return Err(format!(
                        "cannot create `{}`: {e}\nhint: pass a writable folder with `--out`",
                        path.display()
                    ))
                }
                _ => {}
            }
        }
        match crate::dataset::files::classify(&root, &path) {
            crate::dataset::files::Kind::Dir => {}
            crate::dataset::files::Kind::File => {
                return Err(format!(
                "`{}` is a file where the dataset's layout has a folder; nothing written\n{hint}",
                path.display()
            ))
            }
            crate::dataset::files::Kind::Skipped(why) => {
                return Err(format!(
                    "`{}` {why}; nothing is written through it\n{hint}",
                    path.display()
                ))
            }
        }
    }
    Ok(())
}

/// File name of the metadata: `<stem>.json`.
pub fn metadata_file(stem: &str) -> String {
    format!("{stem}.json")
}

/// File names of the float EXRs kept with `--keep-exr`: the final render's passes, and the
/// shadow pass's render (direct light without object shadows in red, with them in green)
/// when it was made.
pub fn exr_files(stem: &str, shadow: bool) -> Vec<String> {
    let mut v = vec![format!("{stem}_passes.exr")];
    if shadow {
        v.push(format!("{stem}_shadow.exr"));
    }
    v
}

/// File names that `--keep-exr` used for the shadow pass before it took one render (its two renders, with
/// and without object shadows): removed when such a sample is written again.
pub fn legacy_exr_files(stem: &str) -> [String; 2] {
    [format!("{stem}_direct.exr"), format!("{stem}_noshadow.exr")]
}

/// Every file a complete sample has: one per requested pass, the metadata, and the EXRs
/// when kept.
pub fn expected_files(stem: &str, passes: &[Pass], keep_exr: bool) -> Vec<String> {
    let mut v: Vec<String> = passes.iter().map(|&p| pass_file(stem, p)).collect();
    if keep_exr {
        v.extend(exr_files(stem, passes.contains(&Pass::Shadow)));
    }
    v.push(metadata_file(stem));
    v
}

/// The split rule of a variant: its built-in config's `splits`, or [`Splits::Standard`] for a
/// variant that is not built in (a `--config` of the user's).
pub fn variant_splits(variant: &str) -> Splits {
    Config::builtin(variant)
        .map(|c| c.splits)
        .unwrap_or(Splits::Standard)
}

/// Whether a variant is broken down by object colour ([`Config::colour_breakdown`] of its
/// built-in config; `false` for a variant that is not built in).
pub fn variant_colour_breakdown(variant: &str) -> bool {
    Config::builtin(variant).is_ok_and(|c| c.colour_breakdown())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_follow_the_published_layout() {
        assert_eq!(stem("camo", 12), "CLEVRTEX_camo_000012");
        assert_eq!(stem("full", 1_234_567), "CLEVRTEX_full_1234567");
        let out = Path::new("data");
        assert_eq!(
            sample_dir(out, "camo", 999),
            Path::new("data/clevrtex_camo/0")
        );
        assert_eq!(
            sample_dir(out, "camo", 4711),
            Path::new("data/clevrtex_camo/4")
        );
        assert_eq!(
            sample_dir(out, "camo", 12345),
            Path::new("data/clevrtex_camo/12")
        );
        assert_eq!(pass_file("S", Pass::Rgb), "S.png");
        assert_eq!(pass_file("S", Pass::Mask), "S_flat.png");
        assert_eq!(pass_file("S", Pass::Depth), "S_depth_0001.png");
        assert_eq!(pass_file("S", Pass::Normal), "S_normal_0001.png");
        assert_eq!(pass_file("S", Pass::Albedo), "S_albedo_0001.png");
        assert_eq!(pass_file("S", Pass::Shadow), "S_shadow_0001.png");
        assert_eq!(metadata_file("S"), "S.json");
        assert_eq!(exr_files("S", true), ["S_passes.exr", "S_shadow.exr"]);
    }

    #[test]
    fn stems_parse_back() {
        assert_eq!(
            parse_stem("CLEVRTEX_full_000123.png", ".png"),
            Some(("CLEVRTEX_full_000123", "full", 123))
        );
        assert_eq!(parse_stem("CLEVRTEX_full_000123_flat.png", ".png"), None);
        assert_eq!(parse_stem("CLEVRTEX_full_12345.png", ".png"), None);
        assert_eq!(
            parse_stem("CLEVRTEX_full_000001_mask.png", "_mask.png"),
            Some(("CLEVRTEX_full_000001", "full", 1))
        );
        let big = stem("full", 1_234_567);
        assert_eq!(
            parse_stem(&format!("{big}.json"), ".json"),
            Some((big.as_str(), "full", 1_234_567))
        );
        assert_eq!(
            parse_file_name("CLEVRTEX_full_000123_flat.png"),
            Some(("CLEVRTEX_full_000123", "full", 123))
        );
        assert_eq!(
            parse_file_name("CLEVRTEX_full_000123_passes.exr"),
            Some(("CLEVRTEX_full_000123", "full", 123))
        );
        assert_eq!(parse_file_name("CLEVRTEX_full_000123.txt"), None);
    }

    #[test]
    fn make_dir_makes_the_layouts_folders_and_refuses_a_link_out() {
        let dir = tempfile::tempdir().unwrap();
        let out = dir.path().join("out");
        let bucket = sample_dir(&out, "camo", 4711);
        make_dir(&out, &bucket).unwrap();
        assert!(bucket.is_dir());
        make_dir(&out, &bucket).unwrap();
        // A link inside `out` is followed (it stays inside); one leading out is refused.
        let inside = sample_dir(&out, "camo", 0);
        std::os::unix::fs::symlink(&bucket, &inside).unwrap();
        make_dir(&out, &inside).unwrap();
        let elsewhere = dir.path().join("elsewhere");
        std::fs::create_dir(&elsewhere).unwrap();
        let linked = sample_dir(&out, "camo", 1000);
        std::os::unix::fs::symlink(&elsewhere, &linked).unwrap();
        let err = make_dir(&out, &linked).unwrap_err();
        assert!(
            err.contains(&format!(
                "`{}` is a symbolic link leading out",
                linked.display()
            )),
            "{err}"
        );
        // The variant folder linked out: refused before a sample folder is made through it.
        let out2 = dir.path().join("out2");
        std::fs::create_dir(&out2).unwrap();
        std::os::unix::fs::symlink(&elsewhere, variant_dir(&out2, "camo")).unwrap();
        let err = make_dir(&out2, &sample_dir(&out2, "camo", 0)).unwrap_err();
        assert!(err.contains("clevrtex_camo` is a symbolic link"), "{err}");
        assert_eq!(std::fs::read_dir(&elsewhere).unwrap().count(), 0);
        // A file where a folder belongs.
        std::fs::write(variant_dir(&out, "full"), b"x").unwrap();
        let err = make_dir(&out, &sample_dir(&out, "full", 0)).unwrap_err();
        assert!(err.contains("is a file where"), "{err}");
    }
}
