//! The published dataset layout (reference §4), in one place: folders, stems and file names. Used by `sample`, `generate`/`render` and `eval`.
//!
//! `OUT/clevrtex_<variant>/<index / 1000>/CLEVRTEX_<variant>_<index:06>{.png, _flat.png,
//! _depth_0001.png, _normal_0001.png, _albedo_0001.png, _shadow_0001.png, .json}`; the pass
//! suffixes come from the pass table ([`crate::passes`]).

use std::path::{Path, PathBuf};

use crate::passes::Pass;

/// File stem of image `index`: `CLEVRTEX_<variant>_<index:06>`.
pub fn stem(variant: &str, index: u64) -> String {
    format!("CLEVRTEX_{variant}_{index:06}")
}

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

/// Folder of one variant: `OUT/clevrtex_<variant>`.
pub fn variant_dir(out: &Path, variant: &str) -> PathBuf {
    out.join(format!("clevrtex_{variant}"))
}

/// Folder of image `index`: `OUT/clevrtex_<variant>/<index / 1000>`.
pub fn sample_dir(out: &Path, variant: &str, index: u64) -> PathBuf {
    variant_dir(out, variant).join((index / 1000).to_string())
}

/// File name of `pass` for the image with file stem `stem`: `<stem><suffix>.png`.
pub fn pass_file(stem: &str, pass: Pass) -> String {
    format!("{stem}{}.png", pass.spec().file_suffix)
}

/// File name of the metadata: `<stem>.json`.
pub fn metadata_file(stem: &str) -> String {
    format!("{stem}.json")
}

/// File names of the float EXRs kept with `--keep-exr`: the final render's passes, and the
/// no-shadow render when the shadow pass was made.
pub fn exr_files(stem: &str, shadow: bool) -> Vec<String> {
    let mut v = vec![format!("{stem}_passes.exr")];
    if shadow {
        v.push(format!("{stem}_noshadow.exr"));
    }
    v
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
        assert_eq!(exr_files("S", true), ["S_passes.exr", "S_noshadow.exr"]);
    }

    #[test]
    fn stems_parse_back() {
        assert_eq!(
            parse_stem("CLEVRTEX_full_000123.png", ".png"),
            Some(("CLEVRTEX_full_000123", "full", 123))
        );
        assert_eq!(parse_stem("CLEVRTEX_full_000123_flat.png", ".png"), None);
        assert_eq!(parse_stem("CLEVRTEX_full_12345.png", ".png"), None);
        let big = stem("full", 1_234_567);
        assert_eq!(
            parse_stem(&format!("{big}.json"), ".json"),
            Some((big.as_str(), "full", 1_234_567))
        );
    }
}
