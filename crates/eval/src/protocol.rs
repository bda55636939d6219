//! How an evaluation is run: the protocol (which community's metrics, and how ground truth is
//! brought to the predictions' resolution) and the options of [`evaluate`](crate::evaluate()).

use crate::dataset::Split;
use crate::metrics::Metric;

/// Which community's metrics are reported by default, and how ground truth is brought to the
/// predictions' resolution (`docs/eval.md` has a table of how the protocols differ).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Protocol {
    /// The public ClevrTex evaluator's metrics; centre crop of side `int(0.8 min(W, H))`,
    /// resized to 128x128 (the benchmark's).
    Clevrtex,
    /// The ClevrTex metrics without crop or resize: predictions at the ground truth's
    /// resolution.
    Native,
    /// DeepMind's FG-ARI (`multi_object_datasets/segmentation_metrics.py`); same crop and resize
    /// as `clevrtex`.
    Deepmind,
    /// The object-centric learning framework's ARI, mIoU, mBO and CorLoc
    /// (`ocl/metrics/masks.py`); same crop and resize as `clevrtex`.
    Ocl,
}

impl Protocol {
    /// Name as on the command line.
    pub fn name(self) -> &'static str {
        match self {
            Protocol::Clevrtex => "clevrtex",
            Protocol::Native => "native",
            Protocol::Deepmind => "deepmind",
            Protocol::Ocl => "ocl",
        }
    }

    /// The protocol called `name`, if any.
    pub fn from_name(name: &str) -> Option<Protocol> {
        [
            Protocol::Clevrtex,
            Protocol::Native,
            Protocol::Deepmind,
            Protocol::Ocl,
        ]
        .into_iter()
        .find(|p| p.name() == name)
    }

    /// The metrics reported when none are chosen.
    pub fn default_metrics(self) -> &'static [Metric] {
        match self {
            Protocol::Clevrtex | Protocol::Native => &Metric::CLEVRTEX,
            Protocol::Deepmind => &Metric::DEEPMIND,
            Protocol::Ocl => &Metric::OCL,
        }
    }

    /// Whether ground truth is centre-cropped and resized to 128x128 (unless the options ask
    /// for the native size).
    pub fn crops(self) -> bool {
        self != Protocol::Native
    }

    /// Where the protocol's definitions come from, for the report's header.
    pub fn source(self) -> &'static str {
        match self {
            Protocol::Clevrtex | Protocol::Native => {
                "karazijal/clevrtex `CLEVRTEX_Evaluator` (ool/clevrtex_eval.py)"
            }
            Protocol::Deepmind => {
                "deepmind/multi_object_datasets `adjusted_rand_index` (segmentation_metrics.py)"
            }
            Protocol::Ocl => {
                "amazon-science/object-centric-learning-framework (ocl/metrics/masks.py)"
            }
        }
    }
}

/// Options of an evaluation.
#[derive(Clone, Debug)]
pub struct Options {
    /// Protocol: the default metrics and the crop/resize.
    pub protocol: Protocol,
    /// Metrics to report; empty for the protocol's own.
    pub metrics: Vec<Metric>,
    /// Score at the dataset's own resolution whatever the protocol (no crop, no resize).
    pub native_size: bool,
    /// Which split; `None` is the default (`test`; all of `outd`).
    pub split: Option<Split>,
    /// Variant name; `None` to infer it from the files.
    pub variant: Option<String>,
    /// Soft masks have no background slot: put `1 - Σ m_k` in front.
    pub no_background: bool,
    /// Score missing predictions as all-background instead of failing.
    pub allow_missing: bool,
    /// Bootstrap resamples for the confidence intervals (0 to skip).
    pub bootstrap: usize,
    /// Seed of the bootstrap.
    pub seed: u64,
}

impl Options {
    /// Whether ground truth is centre-cropped and resized to 128x128.
    pub fn crops(&self) -> bool {
        self.protocol.crops() && !self.native_size
    }
}

impl Default for Options {
    fn default() -> Self {
        Options {
            protocol: Protocol::Clevrtex,
            metrics: Vec::new(),
            native_size: false,
            split: None,
            variant: None,
            no_background: false,
            allow_missing: false,
            bootstrap: 1000,
            seed: 0,
        }
    }
}
