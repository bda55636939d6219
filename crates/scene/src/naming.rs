//! File naming of the published layout (reference §4).

use std::path::PathBuf;

/// File stem of image `index`: `CLEVRTEX_<variant>_<index:06>`.
pub fn stem(variant: &str, index: u64) -> String {
    format!("CLEVRTEX_{variant}_{index:06}")
}

/// Folder of image `index`, relative to the output root: `clevrtex_<variant>/<index / 1000>`.
pub fn sample_dir(variant: &str, index: u64) -> PathBuf {
    PathBuf::from(format!("clevrtex_{variant}")).join((index / 1000).to_string())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_follow_the_published_layout() {
        assert_eq!(stem("camo", 12), "CLEVRTEX_camo_000012");
        assert_eq!(stem("full", 1_234_567), "CLEVRTEX_full_1234567");
        assert_eq!(sample_dir("camo", 999), PathBuf::from("clevrtex_camo/0"));
        assert_eq!(sample_dir("camo", 4711), PathBuf::from("clevrtex_camo/4"));
    }
}
