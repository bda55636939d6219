//! The render benchmark behind `clevrtex bench render`: error against run time of Cycles
//! settings.
//!
//! A fixed set of scenes ([`scenes`]: several variants, fixed seeds) is rendered at each rung
//! of a ladder of settings ([`ladder`]); each render is compared ([`metrics`]) with a
//! high-sample reference of the same scene, cached under `OUT/references/<hash>/` and keyed by
//! the reference scene file, the recipes of the materials it uses (and the content hashes of
//! its user materials, `--materials DIR`) and the Blender version ([`measure`]). The rows go to a CSV ([`csv`]); means over scenes make a table, a summary
//! and a log-log plot of error against time ([`summary`], [`plot`]). [`run`] opens a Blender
//! session per Blender (`clevrtex_render::command_session`) and measures; the command line
//! only parses and prints. See `docs/notes/performance.md`,
//! section `bench`.

pub mod csv;
pub mod ladder;
pub mod measure;
pub mod metrics;
pub mod plot;
pub mod run;
pub mod scenes;
pub mod summary;

pub use ladder::Setting;
pub use measure::{Event, Render, Row};
pub use metrics::Errors;
