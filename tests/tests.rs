//! Integration tests: one binary, one module per topic. They run the real `clevrtex` binary
//! and, where they render, the real Blender (see `util::blender_or_skip`).

mod util;

mod bench;
mod blender_failures;
mod blenders;
mod dataset_card;
mod docs_examples;
mod eval;
mod eval_protocols;
mod export;
mod extreme;
mod generate;
mod gpu_kernels;
mod k8s;
mod ledger;
mod many_writers;
mod materials;
mod passes;
mod pbr;
mod planning;
mod preview;
mod python_package;
mod readers_agree;
mod report;
mod resume;
mod sample;
mod shadow;
mod slurm;
mod splits;
mod structure;
mod suite;
mod trust_paths;
mod user_materials;
mod verify;
mod visibility_bound;
mod workers;
