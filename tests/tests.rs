//! Integration tests: one binary, one module per topic. They run the real `clevrtex` binary
//! and, where they render, the real Blender (see `util::blender_or_skip`).

mod util;

mod bench;
mod blender_failures;
mod blenders;
mod dataset_card;
mod eval;
mod eval_protocols;
mod export;
mod extreme;
mod generate;
mod k8s;
mod ledger;
mod many_writers;
mod materials;
mod passes;
mod preview;
mod python_package;
mod report;
mod resume;
mod sample;
mod shadow;
mod slurm;
mod splits;
mod trust_paths;
mod verify;
mod workers;
