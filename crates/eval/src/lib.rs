//! The ClevrTex benchmark's metrics (mIoU, ARI, ARI-FG, MSE, ...), exact and fast.
#![deny(missing_docs)]
