//! One variant's part of a `generate` run, prepared ([`prepare`]): the config with the
//! command line's changes, its numbers checked, the first layouts drawn before any Blender
//! starts, the jobs (each image sampled when a worker takes it), the failure ledger and the
//! run's manifest as planned.

use std::collections::BTreeSet;
use std::path::Path;
use std::sync::Arc;

use clevrtex_dataset::{layout, manifest};
use clevrtex_materials::Catalogue;
use clevrtex_scene::config::{check_index_end, parse_passes, within, Overrides};
use clevrtex_scene::{shard::Shard, Config, Pass, SampleRequest};

use crate::pool::{Job, Jobs};
use crate::scene_jobs::RunJobs;

/// Layouts drawn by `generate` before any Blender starts, to refuse impossible configs.
const PREFLIGHT_LAYOUTS: usize = 20;

/// The most layout attempts per image (`--max-attempts`).
pub const MAX_ATTEMPTS: u32 = 1000;

/// One variant's part of a `generate` run: its images `start..start + count` of `total`, the
/// share `shard` of them, with `seed`.
#[derive(Debug, Clone, Copy)]
pub struct Part {
    /// First index.
    pub start: u64,
    /// Images.
    pub count: u64,
    /// Size of the whole variant (fixes the splits); `None`: `start + count`.
    pub total: Option<u64>,
    /// This process's share.
    pub shard: Shard,
    /// Run seed.
    pub seed: u64,
}

/// What a `generate` run asks for one variant.
pub struct Request<'a> {
    /// The variant's config as read (built in or `--config`).
    pub config: Config,
    /// The catalogue (built-in plus `--materials`).
    pub catalogue: &'a Catalogue,
    /// `--material-set`, and whether `user` is the default ([`Config::apply_material_set`]).
    pub material_set: (Option<&'a str>, bool),
    /// `--layout-stream`, the size and sampling flags.
    pub overrides: &'a Overrides,
    /// `--max-attempts`.
    pub max_attempts: u32,
    /// `--passes` (default: every pass).
    pub passes: Option<&'a [String]>,
    /// The images.
    pub part: Part,
    /// `--out`.
    pub out: &'a Path,
    /// `--keep-exr`.
    pub keep_exr: bool,
    /// The manifest's fields of the run itself (tool, command, suite, `--mix-settings`); the
    /// variant's are filled in.
    pub manifest: manifest::Manifest,
}

/// A variant's part ready to run (or to plan with `--estimate`).
pub struct Prepared {
    /// The jobs, the failure ledger, the materials used.
    pub jobs: RunJobs,
    /// The manifest as planned.
    pub plan: manifest::Plan,
    /// The config's split rule.
    pub splits: clevrtex_scene::names::Splits,
    /// The settings in words: variant, size, samples, passes (`--estimate`'s first line).
    pub what: String,
}

/// Prepare a variant's part as `req` asks: every refusal before any Blender starts.
pub fn prepare(req: Request) -> Result<Prepared, String> {
    let mut config = req.config;
    let (set, default_user) = req.material_set;
    config.apply_material_set(req.catalogue, set, default_user)?;
    let used: BTreeSet<String> = config
        .objects
        .materials
        .iter()
        .chain(&config.background.materials)
        .cloned()
        .collect();
    config.apply_overrides(req.overrides)?;
    within("--max-attempts", req.max_attempts, MAX_ATTEMPTS)?;
    // Fail before starting Blender when no layout could ever be drawn, as `sample` does.
    clevrtex_scene::sample::check_feasible(&config).map_err(|e| e.to_string())?;
    let passes = match req.passes {
        Some(list) => parse_passes(list)?,
        None => Pass::ALL.to_vec(),
    };
    config.base.passes = passes.clone();
    let part = req.part;
    if part.count == 0 {
        return Err(
            "`-n 0` asks for no images\nhint: pass the number of images, e.g. `-n 100`".into(),
        );
    }
    let end = part
        .start
        .checked_add(part.count)
        .ok_or("`--start` + `-n` overflows\nhint: pass smaller numbers")?;
    check_index_end(part.start, end)?;
    let total = part.total.unwrap_or(end);
    if total < end {
        return Err(format!("`--total {total}` is smaller than the last index + 1 (`{end}`)\nhint: pass the size of the whole dataset"));
    }
    let (shard, start, seed) = (part.shard, part.start, part.seed);
    // Draw the first layouts before starting Blender: a config whose objects can never be
    // placed fails here once (exit 1), as in `sample`, not once per image into the ledger.
    for index in shard.iter(start, end).take(PREFLIGHT_LAYOUTS) {
        let req = SampleRequest {
            seed,
            index,
            attempt: 0,
            total,
        };
        clevrtex_scene::sample(&config, &req).map_err(|e| e.to_string())?;
    }
    let config = Arc::new(config);
    let variant = config.name.clone();
    // Job `i` is made when a worker takes it: no list of the run's jobs is held, so
    // `-n 100000000` runs in bounded memory.
    let make = {
        let (config, variant, passes) = (Arc::clone(&config), variant.clone(), passes.clone());
        move |i: u64| {
            let index = shard.nth(start, end, i);
            let config = Arc::clone(&config);
            Job {
                index,
                variant: variant.clone(),
                stem: clevrtex_scene::stem(&variant, index),
                passes: passes.clone(),
                scene: Arc::new(move |attempt| {
                    let req = SampleRequest {
                        seed,
                        index,
                        attempt,
                        total,
                    };
                    clevrtex_scene::sample(&config, &req).map_err(|e| e.to_string())
                }),
                resample: true,
                source: None,
            }
        }
    };
    let has_stem = {
        let variant = variant.clone();
        move |stem: &str| {
            layout::parse_stem(stem, "")
                .is_some_and(|(_, v, index)| v == variant && shard.contains(start, end, index))
        }
    };
    let r = &config.base.render;
    let what = format!(
        "`{variant}` at {}x{}, {} samples{}, passes {}",
        r.width,
        r.height,
        r.samples,
        r.adaptive_threshold
            .map(|t| format!(" (adaptive threshold {t})"))
            .unwrap_or_default(),
        passes
            .iter()
            .map(|p| p.name())
            .collect::<Vec<_>>()
            .join(",")
    );
    let plan = manifest::Plan {
        run: manifest::Manifest {
            variant: variant.clone(),
            seed,
            layout_stream: Some(config.layout_stream().to_string()),
            config_hash: config.content_hash(),
            render: serde_json::to_value(&config.base.render).ok(),
            start,
            end,
            total,
            shard: [shard.k, shard.n],
            ..req.manifest
        },
        passes,
        keep_exr: req.keep_exr,
    };
    Ok(Prepared {
        jobs: RunJobs {
            jobs: Jobs::lazy(shard.count(start, end), make, has_stem),
            ledger: layout::variant_dir(req.out, &variant).join("failures.jsonl"),
            used,
        },
        plan,
        splits: config.splits,
        what,
    })
}
