//! The library parts of `clevrtex materials`: the contact sheet's stitching ([`sheet`]), the
//! distinctness statistics of rendered tiles ([`stats`], also the CIELAB conversion the report
//! uses) and the dataset figures of `materials measure` ([`figures`]). The Blender renders
//! stay with the command (`crates/core/cmd_materials.rs`).

pub mod figures;
pub mod sheet;
pub mod stats;
