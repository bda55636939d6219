//! The run manifest (`MANIFEST-<start>-<end>-<k>of<n>.json`): its types and reading
//! (`types.rs`: what a run made, the union of runs) and its writing (`write.rs`: the hashes of a
//! run's files, the atomic write, the [`Plan`] of a `generate` run).

pub mod types;
pub mod write;

pub use types::*;
pub use write::*;
