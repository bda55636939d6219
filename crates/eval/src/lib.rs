//! The ClevrTex benchmark's metrics (mIoU, ARI, ARI-FG, MSE, ...), exact and fast.
//!
//! [`evaluate`] scores a directory of predictions against a dataset in the published layout
//! (`clevrtex_<variant>/<index // 1000>/CLEVRTEX_<variant>_<index:06>{.png,_flat.png,.json}`),
//! in parallel over images. [`score_image`] scores one image from label arrays; every metric
//! agrees with the public evaluator to 1e-6 (see `docs/eval.md` for the definitions, including
//! where ours deliberately differ: mSC, exact ARI).
//!
//! ```
//! use clevrtex_eval::{score_image, Metric};
//! // Truth: background and one object; prediction: the same partition, other ids.
//! let truth = [0, 0, 1, 1];
//! let pred = [2, 2, 0, 0];
//! let s = score_image(&truth, &pred, 3, None);
//! assert_eq!(s.get(Metric::Ari), Some(1.0));
//! assert_eq!(s.get(Metric::MIoUGt), Some(1.0));
//! assert_eq!(s.get(Metric::Mse), None); // no reconstruction given
//! ```
#![deny(missing_docs)]

pub mod dataset;
pub mod error;
pub mod evaluate;
mod image;
pub mod lsa;
pub mod meta;
pub mod metrics;
pub mod output;
pub mod predict;
mod protocol;
pub mod read;
/// The benchmark's crop and resize (in `clevrtex-dataset`, which the export shares it with).
pub use clevrtex_dataset::resize;

pub use dataset::Split;
pub use error::EvalError;
pub use evaluate::{evaluate, Options, Protocol, Report};
pub use metrics::{score_image, Metric, PredRgb, Recon, Scores};
