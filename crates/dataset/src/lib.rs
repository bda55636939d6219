//! Everything about a clevrtex dataset on disk: the published layout and its names
//! ([`layout`], with the names a scene file carries from `clevrtex_scene::names`), the one
//! reader of a dataset folder ([`dataset`]: the walk, capped reads beneath the root, the typed
//! metadata view, the splits), the run manifests ([`manifest`]: types, reading, writing), the
//! one atomic writer ([`atomic`]), the one check of an output path ([`out_path`]), the range lock of a dataset folder ([`run_lock`]),
//! `clevrtex verify` ([`verify`]), what every export reads ([`export`]), the WebDataset
//! `export` ([`webdataset`]), the COCO export ([`coco`]), the public loader's crop and resize
//! ([`resize`]) and the dataset card ([`card`]).
//!
//! The feature `tools` (default) holds [`run_lock`], `sample`'s scene files (written under
//! the range's lock, read back for `render`), `verify`, `export`, `webdataset`, `coco`, `card`
//! and [`exr`]; the readers (`eval`, `report`, the Python package) build without it.
//!
//! Nothing here starts Blender: `clevrtex-render` writes samples through [`layout`],
//! [`atomic`] and [`manifest`], and every reader (`verify`, `export`, `report`, `eval`, the
//! Python `Dataset`) reads through [`dataset`].
//!
//! ```
//! use clevrtex_dataset::layout;
//! use std::path::Path;
//!
//! let dir = layout::sample_dir(Path::new("out"), "camo", 4711);
//! assert_eq!(dir, Path::new("out/clevrtex_camo/4"));
//! let stem = layout::stem("camo", 4711);
//! assert_eq!(layout::metadata_file(&stem), "CLEVRTEX_camo_004711.json");
//! ```
#![deny(missing_docs)]

pub mod atomic;
#[cfg(feature = "tools")]
pub mod card;
#[cfg(feature = "tools")]
mod card_parts;
#[cfg(feature = "tools")]
pub mod coco;
pub mod dataset;
pub mod error;
#[cfg(feature = "tools")]
pub mod export;
#[cfg(feature = "tools")]
pub mod exr;
pub mod fingerprint;
pub mod ids;
pub mod layout;
pub mod manifest;
pub mod out_path;
pub mod png;
pub mod quantity;
pub mod resize;
#[cfg(feature = "tools")]
pub mod run_lock;
#[cfg(feature = "tools")]
pub mod sample_run;
#[cfg(feature = "tools")]
pub mod scene_files;
#[cfg(feature = "tools")]
pub mod scene_read;
#[cfg(feature = "tools")]
pub mod suite;
#[cfg(feature = "tools")]
pub mod verify;
#[cfg(feature = "tools")]
pub mod webdataset;

pub use error::{Error, IoFailure};
