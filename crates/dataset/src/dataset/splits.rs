//! The one split rule every reader follows ([`splits`]: the recorded `split`, else by position)
//! and reading a sample's recorded split cheaply ([`read_recorded_split`]).

use std::path::Path;

use serde_json::Value;

use super::files::{read, MAX_METADATA_BYTES};
use super::metadata::recorded_split;
use super::walk::{Dataset, SampleRef};
use crate::layout;

/// The split of each sample of one variant, the samples given in index order with the split
/// each records ([`recorded_split`]): the one rule every reader follows (`Dataset`, `eval`,
/// `export`, `verify`, `report`). The recorded split is authoritative: `generate` fixes it from
/// `--total` and a dataset grown with `--start` keeps it. A sample that records none (the
/// published ClevrTex) gets the public loader's position rule among the samples given (test the
/// first `int(0.1 N)`, val up to `int(0.2 N)`, train the rest; a test-only variant all test).
pub fn splits(variant: &str, recorded: &[Option<layout::Split>]) -> Vec<layout::Split> {
    let rule = layout::variant_splits(variant);
    let n = recorded.len() as u64;
    recorded
        .iter()
        .enumerate()
        .map(|(i, r)| r.unwrap_or_else(|| layout::Split::of(rule, i as u64, n)))
        .collect()
}

/// Where the splits every clevrtex reader gives (the recorded ones, [`splits`]) differ from
/// what the public loader gives the same samples (its position rule over the samples found,
/// ignoring what they record), in one sentence; `None` when they agree. They differ when a
/// dataset was grown with another `--total` than its first runs (`generate` refuses that
/// unless asked to) or is not complete: `clevrtex eval --split test` and the public evaluator
/// would then score other test sets.
pub fn loader_disagreement(variant: &str, recorded: &[Option<layout::Split>]) -> Option<String> {
    let ours = splits(variant, recorded);
    let theirs = splits(variant, &vec![None; recorded.len()]);
    let differ: Vec<usize> = (0..ours.len()).filter(|&i| ours[i] != theirs[i]).collect();
    let &first = differ.first()?;
    Some(format!(
        "the recorded splits ({}) differ from the public loader's position rule over these {} samples ({}) at {} position(s), e.g. position {first}: recorded `{}`, the loader `{}`",
        split_sizes(&ours),
        ours.len(),
        split_sizes(&theirs),
        differ.len(),
        ours[first].name(),
        theirs[first].name()
    ))
}

/// How many of `splits` are in each split, for messages: `test 0, val 0, train 4`.
pub fn split_sizes(splits: &[layout::Split]) -> String {
    layout::Split::ALL
        .iter()
        .map(|s| format!("{} {}", s.name(), splits.iter().filter(|x| *x == s).count()))
        .collect::<Vec<_>>()
        .join(", ")
}

/// Only the `split` of a sample's metadata (the rest skipped unparsed, so reading the splits
/// of a large dataset costs little more than listing it).
#[derive(serde::Deserialize)]
struct SplitOnly {
    #[serde(default)]
    split: Value,
}

/// The split the metadata file `path` (of a sample of `variant`, in the dataset whose
/// canonical root is `root`) records ([`recorded_split`]), reading only that key; `Err` says
/// why not in one line, without the path (unreadable, not JSON, a bad `split`).
pub fn read_recorded_split(
    root: &Path,
    path: &Path,
    variant: &str,
) -> Result<Option<layout::Split>, String> {
    let bytes = read(root, path, MAX_METADATA_BYTES)?;
    let only: SplitOnly =
        serde_json::from_slice(&bytes).map_err(|e| format!("is not valid metadata: {e}"))?;
    recorded_split(&only.split, variant, "").map_err(|e| format!("key `split` {}", e.what))
}

impl Dataset {
    /// The split sample `s`'s metadata records ([`read_recorded_split`]).
    pub fn read_recorded_split(&self, s: &SampleRef) -> Result<Option<layout::Split>, String> {
        read_recorded_split(&self.root, &s.metadata_path(), &s.variant)
    }
}
