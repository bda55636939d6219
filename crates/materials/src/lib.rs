//! The material catalogue: procedural materials as data, read and validated in Rust and
//! built by the Blender bridge.
#![deny(missing_docs)]

/// The catalogue file, embedded so an installed binary never hunts for it.
pub const CATALOGUE_JSON: &str = include_str!("../../../materials/catalogue.json");
