//! Pure, seeded sampler of ClevrTex-style scene layouts.
//!
//! No I/O, no processes, no global RNG: every function takes its inputs and returns its
//! outputs. The [`scene_file`] types are the contract with the Blender bridge.
#![deny(missing_docs)]

pub mod scene_file;

pub use scene_file::{Pass, SceneFile};
