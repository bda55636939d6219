//! Pure, seeded sampler of ClevrTex-style scene layouts.
//!
//! No I/O, no processes, no global RNG: every function takes its inputs and returns its
//! outputs. The [`scene_file`] types are the contract with the Blender bridge.
//!
//! ```
//! use clevrtex_scene::{config::Config, sample, metadata, SampleRequest};
//!
//! let config = Config::builtin("camo").unwrap();
//! let req = SampleRequest { seed: 7, index: 12, attempt: 0, total: 1000 };
//! let scene = sample(&config, &req).unwrap();
//! assert_eq!(scene.stem, "CLEVRTEX_camo_000012");
//! // CAMO: one material on every object and on the background.
//! assert!(scene.objects.iter().all(|o| o.material.name == scene.backdrop.material.name));
//! // Image 12 does not depend on which other images were sampled.
//! assert_eq!(scene, sample(&config, &req).unwrap());
//! let meta = metadata(&scene);
//! assert_eq!(meta.num_objects, scene.objects.len());
//! ```
#![deny(missing_docs)]

pub mod bounds;
pub mod camera;
pub mod config;
pub mod json;
pub mod metadata;
pub mod names;
pub mod passes;
pub mod quality;
mod rng;
pub mod sample;
pub mod scene_file;
pub mod shard;
pub mod suite;
pub mod text;
pub mod visibility;

pub use camera::{look_at_matrix, project, track_matrix};
pub use config::{Config, ConfigError};
pub use json::to_pretty_json;
pub use metadata::{metadata, ClevrMetadata};
pub use names::stem;
pub use rng::{SceneRng, SHARED_STREAM};
pub use sample::{sample, SampleError, SampleRequest};
pub use scene_file::{Pass, SceneFile};
