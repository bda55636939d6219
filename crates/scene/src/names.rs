//! The names a scene file itself carries, part of its contract with the Blender bridge and
//! the published layout: its `stem` (`CLEVRTEX_<variant>_<index:06>`), its variant's name
//! ([`variant_name_problem`]), its `split` ([`Split`], by the rule [`Splits`]), the file names
//! its metadata records ([`pass_file`]) and the shapes the bridge builds ([`KNOWN_SHAPES`]).
//! The dataset layout on disk (folders, every file name, reading and writing) is the
//! `clevrtex-dataset` crate's (`clevrtex_dataset::layout`), which uses these.

use std::ops::Range;

use serde::{Deserialize, Serialize};

use crate::passes::Pass;

/// File stem of image `index`: `CLEVRTEX_<variant>_<index:06>`.
pub fn stem(variant: &str, index: u64) -> String {
    format!("CLEVRTEX_{variant}_{index:06}")
}

/// Longest variant name: it becomes part of folder and file names.
pub const MAX_VARIANT_NAME: usize = 64;

/// Why `name` cannot be a variant's name, or `None` when it can. A variant's name becomes part
/// of folder and file names (`clevrtex_<variant>`, `CLEVRTEX_<variant>_<index>`), so it must be
/// 1 to [`MAX_VARIANT_NAME`] ASCII letters, digits, `_` or `-`: one path component that is
/// never `.`, `..` or absolute, whatever file it was read from.
pub fn variant_name_problem(name: &str) -> Option<String> {
    if name.is_empty() || name.len() > MAX_VARIANT_NAME {
        return Some(format!(
            "must be 1 to {MAX_VARIANT_NAME} characters (it is used in file names)"
        ));
    }
    if !name
        .chars()
        .all(|c| c.is_ascii_alphanumeric() || c == '_' || c == '-')
    {
        return Some(
            "must be ASCII letters, digits, `_` or `-` (it is used in file names)".to_string(),
        );
    }
    None
}

/// File name of `pass` for the image with file stem `stem`: `<stem><suffix>.png`.
pub fn pass_file(stem: &str, pass: Pass) -> String {
    format!("{stem}{}.png", pass.spec().file_suffix)
}

/// Shapes the bridge can build, the four main ones first.
pub const KNOWN_SHAPES: [&str; 8] = [
    "cube",
    "sphere",
    "cylinder",
    "monkey",
    "cone",
    "torus",
    "icosahedron",
    "teapot",
];

/// Which images go to which split.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Splits {
    /// First 10% of the run's indices `test`, next 10% `val`, the rest `train`.
    Standard,
    /// Every image is `test` (the OOD set).
    TestOnly,
}

/// A split of the published dataset.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord)]
pub enum Split {
    /// The first `int(0.1 N)` images.
    Test,
    /// The next `int(0.2 N) - int(0.1 N)`.
    Val,
    /// The rest.
    Train,
}

impl Split {
    /// Every split, in the order of the published files.
    pub const ALL: [Split; 3] = [Split::Test, Split::Val, Split::Train];

    /// The split named `name` (`test`, `val` or `train`); `None` for any other text.
    pub fn parse(name: &str) -> Option<Split> {
        Split::ALL.into_iter().find(|s| s.name() == name)
    }

    /// `test`, `val` or `train`.
    pub fn name(self) -> &'static str {
        match self {
            Split::Test => "test",
            Split::Val => "val",
            Split::Train => "train",
        }
    }

    /// The positions of this split among `total` images with the rule `splits`, exactly as
    /// the public loader cuts them: test `[0, int(0.1 N))`, val `[int(0.1 N), int(0.2 N))`,
    /// train the rest (Python's float products, truncated). A test-only set is all test.
    pub fn range(self, splits: Splits, total: u64) -> Range<u64> {
        let (t, v) = match splits {
            Splits::TestOnly => (total, total),
            Splits::Standard => {
                let t = (0.1 * total as f64) as u64;
                (t, ((0.2 * total as f64) as u64).max(t))
            }
        };
        match self {
            Split::Test => 0..t,
            Split::Val => t..v,
            Split::Train => v..total,
        }
    }

    /// The split of image `index` in a dataset of `total` images (see [`Split::range`]).
    pub fn of(splits: Splits, index: u64, total: u64) -> Split {
        [Split::Test, Split::Val]
            .into_iter()
            .find(|s| s.range(splits, total).contains(&index))
            .unwrap_or(Split::Train)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn variant_names_are_one_plain_path_component() {
        for ok in ["camo", "my_variant-2", "A"] {
            assert_eq!(variant_name_problem(ok), None, "{ok}");
        }
        let long = "x".repeat(MAX_VARIANT_NAME + 1);
        for bad in [
            "",
            ".",
            "..",
            "a/b",
            "/etc",
            "a b",
            "caf\u{e9}",
            "a\0b",
            long.as_str(),
        ] {
            assert!(variant_name_problem(bad).is_some(), "{bad:?}");
        }
    }

    #[test]
    fn splits_follow_the_index() {
        let s = Splits::Standard;
        assert_eq!(Split::of(s, 0, 100), Split::Test);
        assert_eq!(Split::of(s, 9, 100), Split::Test);
        assert_eq!(Split::of(s, 10, 100), Split::Val);
        assert_eq!(Split::of(s, 19, 100), Split::Val);
        assert_eq!(Split::of(s, 20, 100), Split::Train);
        assert_eq!(Split::of(Splits::TestOnly, 99, 100), Split::Test);
        // The public loader's int(0.1 * 15) = 1: index 1 is `val`.
        assert_eq!(Split::of(s, 1, 15), Split::Val);
        assert_eq!(Split::Val.range(s, 15), 1..3);
        assert_eq!(Split::Train.range(Splits::TestOnly, 7), 7..7);
    }
}
