//! What `clevrtex` draws of a dataset, as a library: the HTML report of `clevrtex report`
//! ([`report`]), the preview contact sheet of `clevrtex preview` ([`preview`]), and the
//! material contact sheet, distinctness statistics and dataset figures of `clevrtex materials`
//! ([`materials`]). The command line (`crates/core`) parses arguments, calls these and prints.
//!
//! Datasets are untrusted input (`docs/security.md`): every file is read through
//! `clevrtex_dataset::dataset` (no link out of the dataset followed, no FIFO or device opened,
//! capped reads), and a PNG's size is checked from its header before it is decoded.

pub mod font;
pub mod materials;
pub mod preview;
pub mod report;
