//! Errors of `clevrtex eval`: each names the offending value or path and says what to do.

use std::fmt::Write as _;
use std::path::PathBuf;

/// Largest number of segment slots per image (ids `0..MAX_SLOTS`). The matching is cubic in
/// the number of slots, so a stray huge id must be an error rather than an hour of work.
pub const MAX_SLOTS: usize = 1024;

/// Everything that can go wrong while evaluating.
#[derive(Debug, thiserror::Error)]
pub enum EvalError {
    /// A file or directory could not be read.
    ///
    /// The cause is a plain field, not an error `source`, so it is printed once, before the
    /// hint, and not again after it by an error-chain printer.
    #[error("cannot read `{}`: {cause}\nhint: check that the path exists and is readable", path.display())]
    Io {
        /// The path.
        path: PathBuf,
        /// The cause.
        cause: std::io::Error,
    },
    /// A file is damaged or not what its name says.
    #[error("cannot decode `{}`: {reason}\nhint: {hint}", path.display())]
    Corrupt {
        /// The file.
        path: PathBuf,
        /// What is wrong with it.
        reason: String,
        /// What to do.
        hint: String,
    },
    /// A prediction's shape differs from the ground truth's.
    #[error("shape mismatch in `{}`: prediction is {pred}, ground truth is {truth}\nhint: {hint}", path.display())]
    ShapeMismatch {
        /// The prediction file.
        path: PathBuf,
        /// The prediction's shape.
        pred: String,
        /// The expected shape.
        truth: String,
        /// What to do.
        hint: String,
    },
    /// Predictions are missing for some ground-truth samples.
    #[error("{}", missing_message(*count, *total, first, skipped))]
    MissingPredictions {
        /// How many are missing.
        count: usize,
        /// How many samples were evaluated.
        total: usize,
        /// The first few missing stems.
        first: Vec<String>,
        /// Files of those stems that were found but not read, with the reason.
        skipped: Vec<String>,
    },
    /// The ground-truth directory has no samples.
    #[error("no ground-truth samples `{pattern}` under `{}`\nhint: pass the dataset directory (the one holding `clevrtex_<variant>/` or the numbered folders), and `--variant` if the files use another variant name", dir.display())]
    NoSamples {
        /// The directory searched.
        dir: PathBuf,
        /// The file pattern looked for.
        pattern: String,
    },
    /// The ground truth holds several variants and none was chosen.
    #[error("`{}` holds samples of several variants: {}\nhint: choose one with `--variant`", dir.display(), variants.iter().map(|v| format!("`{v}`")).collect::<Vec<_>>().join(", "))]
    SeveralVariants {
        /// The directory searched.
        dir: PathBuf,
        /// The variants found.
        variants: Vec<String>,
    },
    /// The ground-truth indices are not contiguous.
    #[error("ground truth has a gap: index `{missing}` is missing (found {first}..={last}, {count} samples)\nhint: every index must be present (a dataset whose metadata records no split, like the published ClevrTex, is split by position in the index sequence); restore the missing sample or evaluate a complete dataset")]
    GtGap {
        /// The first missing index.
        missing: u64,
        /// The lowest index present.
        first: u64,
        /// The highest index present.
        last: u64,
        /// How many samples were found.
        count: usize,
    },
    /// The same sample occurs twice.
    #[error("duplicate {what} `{stem}`: `{}` and `{}`\nhint: keep exactly one of them", a.display(), b.display())]
    Duplicate {
        /// `ground-truth sample` or `prediction`.
        what: &'static str,
        /// The sample's stem.
        stem: String,
        /// The first file.
        a: PathBuf,
        /// The second file.
        b: PathBuf,
    },
    /// A ground-truth sample lacks one of its files.
    #[error("ground-truth sample `{stem}` has no `{}`\nhint: every `<stem>.png` needs `<stem>_flat.png` and `<stem>.json` beside it; regenerate or re-download the sample", path.display())]
    GtIncomplete {
        /// The sample's stem.
        stem: String,
        /// The missing file.
        path: PathBuf,
    },
    /// A ground-truth sample's file is not read: a link out of the ground-truth folder, a
    /// FIFO, a socket or a device.
    #[error("ground-truth sample `{stem}`: `{}` {why}: it is not read, and nothing is scored without it\nhint: every file of the ground truth must be a regular file inside its folder (a link only to a file inside it); copy the file in instead of linking it", path.display())]
    GtNotRead {
        /// The sample's stem.
        stem: String,
        /// The file.
        path: PathBuf,
        /// Why it is not read, one line.
        why: String,
    },
    /// The chosen split holds no sample.
    #[error("the `{split}` split of `{}` is empty: it has {total} samples in all ({sizes})\nhint: each sample's split is the one its metadata records (`generate` fixes it from `--total`: test the first int(0.1 N), val up to int(0.2 N), train the rest); use `--split all` for small datasets", gt.display())]
    EmptySplit {
        /// The split.
        split: &'static str,
        /// The ground-truth folder.
        gt: PathBuf,
        /// Samples in all.
        total: usize,
        /// Samples per split, `test 0, val 0, train 4`.
        sizes: String,
    },
    /// A bad combination of options.
    #[error("{message}\nhint: {hint}")]
    Usage {
        /// What is wrong.
        message: String,
        /// What to do.
        hint: String,
    },
}

impl EvalError {
    /// `path` is not a readable directory: says whether it is missing or something else.
    pub fn not_a_dir(path: &std::path::Path) -> EvalError {
        let (kind, what) = if path.exists() {
            (std::io::ErrorKind::InvalidInput, "not a directory")
        } else {
            (std::io::ErrorKind::NotFound, "no such directory")
        };
        EvalError::Io {
            path: path.to_path_buf(),
            cause: std::io::Error::new(kind, what),
        }
    }
}

fn missing_message(count: usize, total: usize, first: &[String], skipped: &[String]) -> String {
    let mut s = format!("no prediction for {count} of {total} ground-truth samples, e.g. ");
    for (i, stem) in first.iter().enumerate() {
        if i > 0 {
            s.push_str(", ");
        }
        let _ = write!(s, "`{stem}`");
    }
    for note in skipped {
        let _ = write!(s, "\nnot read: {note}");
    }
    if !skipped.is_empty() {
        s.push_str("\nhint: a prediction must be a regular file (a link only to a file inside the predictions directory)");
    }
    s.push_str("\nhint: name predictions `<stem>_mask.png`, `<stem>.npy` or `<stem>.npz` anywhere under the predictions directory, or pass `--allow-missing` to score them as all-background");
    s
}

/// Shorthand for a [`EvalError::Corrupt`].
pub(crate) fn corrupt(path: &std::path::Path, reason: impl Into<String>, hint: &str) -> EvalError {
    EvalError::Corrupt {
        path: path.to_path_buf(),
        reason: reason.into(),
        hint: hint.to_string(),
    }
}
