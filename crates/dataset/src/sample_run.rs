//! `clevrtex sample`'s run: the scene files of a range (one shard of it) sampled in parallel
//! and written ([`run`]), streamed in chunks so memory stays bounded whatever the count, then
//! made durable and committed by the range's manifest (`crate::scene_files`). A writer like
//! `generate`: under the range's lock (`crate::run_lock`), the folder checked and the range's
//! commit removed before any file is replaced ([`run`]).

use std::path::Path;
use std::sync::atomic::{AtomicBool, Ordering};

use clevrtex_scene::{config::Config, sample, shard::Shard, SampleRequest};
use rayon::prelude::*;

use crate::layout::sample_dir;
use crate::scene_files;

/// Indices sampled and written per batch (bounds memory for any `-n`).
const SAMPLE_CHUNK: usize = 1 << 16;

/// What to sample: the images `start..end` of `total` that `shard` holds, with `seed`, into
/// `out`, on `threads` threads (0: one per core).
pub struct Request<'a> {
    /// The variant config.
    pub config: &'a Config,
    /// Output root.
    pub out: &'a Path,
    /// Run seed.
    pub seed: u64,
    /// First index.
    pub start: u64,
    /// One past the last index.
    pub end: u64,
    /// Size of the whole dataset (fixes the splits).
    pub total: u64,
    /// This process's share.
    pub shard: Shard,
    /// Worker threads (0: one per core).
    pub threads: usize,
    /// This process's command line, recorded in the range's lock.
    pub command: Vec<String>,
}

/// How a run ended.
pub enum Sampled {
    /// Every file written (this many) and committed.
    Done(u64),
    /// Stopped by `interrupted`: the files written are whole, no manifest commits them (a
    /// rerun rewrites them).
    Interrupted,
}

/// Sample and write the scene files `req` asks for; `written_one` is called after each image,
/// `interrupted` (Ctrl-C) finishes the files being written and stops. Under the range's lock
/// (a live overlapping `sample` or `generate` refuses it), and refused with nothing changed
/// when the folder holds rendered samples or scene files of another run
/// ([`scene_files::check_folder`], [`check_replaced`]).
pub fn run(
    req: &Request,
    interrupted: &AtomicBool,
    written_one: &(dyn Fn() + Sync),
) -> Result<Sampled, String> {
    let Request {
        config, out, seed, ..
    } = *req;
    let (shard, total) = (req.shard, req.total);
    let vdir = crate::layout::variant_dir(out, &config.name);
    let mut manifest = scene_files::ScenesManifest {
        format: scene_files::FORMAT.into(),
        version: 1,
        variant: config.name.clone(),
        seed,
        layout_stream: config.layout_stream().to_string(),
        start: req.start,
        end: req.end,
        total,
        shard: [shard.k, shard.n],
        files: 0,
        tool_version: env!("CARGO_PKG_VERSION").into(),
    };
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(req.threads)
        .build()
        .map_err(|e| format!("cannot start worker threads: {e}"))?;
    // Not beside a dataset's variants (before anything is made).
    scene_files::check_out(out, &config.name)?;
    // One writer per range, as `generate`: the lock makes the variant folder (not a link out
    // of `--out`); under it, nothing is replaced that this run did not write.
    let _lock = crate::run_lock::RunLock::acquire(
        &vdir,
        req.start,
        req.end,
        manifest.shard,
        req.command.clone(),
    )?;
    scene_files::check_folder(&vdir, &manifest)?;
    // What a killed commit left beside the manifests.
    crate::atomic::remove_stale_temps(&vdir);
    pool.install(|| check_replaced(req, &manifest))?;
    scene_files::invalidate(&vdir, &manifest).map_err(|e| {
        format!(
            "cannot remove the earlier commit `{}`: {e}\nhint: check permissions under `--out`",
            vdir.join(manifest.name()).display()
        )
    })?;
    // First index >= start with index % n == k, then every n-th, streamed in chunks: memory
    // stays bounded whatever `-n` is, and files appear in index order chunk by chunk.
    let mut indices = shard.iter(req.start, req.end).peekable();
    let stop = AtomicBool::new(false);
    let mut written = 0u64;
    let mut last_dir = None;
    while indices.peek().is_some() {
        let chunk: Vec<u64> = indices.by_ref().take(SAMPLE_CHUNK).collect();
        for &i in &chunk {
            let d = sample_dir(out, &config.name, i);
            if last_dir.as_ref() != Some(&d) {
                // A folder of the layout that is a link out of `--out` is refused, naming it.
                crate::layout::make_dir(out, &d)?;
                // What a killed run of this host left there (its owner is dead).
                crate::atomic::remove_stale_temps(&d);
                last_dir = Some(d);
            }
        }
        // Results come back in index order, so the error reported is the first one by index.
        let results: Vec<Result<(), String>> = pool.install(|| {
            chunk
                .par_iter()
                .map(|&index| {
                    if stop.load(Ordering::Relaxed) || interrupted.load(Ordering::Relaxed) {
                        return Ok(());
                    }
                    let req = SampleRequest {
                        seed,
                        index,
                        attempt: 0,
                        total,
                    };
                    let result = sample(config, &req)
                        .map_err(|e| e.to_string())
                        .and_then(|scene| write_scene(out, &config.name, &scene));
                    if result.is_err() {
                        stop.store(true, Ordering::Relaxed);
                    }
                    written_one();
                    result
                })
                .collect()
        });
        if interrupted.load(Ordering::SeqCst) {
            let _ = crate::atomic::sync_filesystem(out);
            return Ok(Sampled::Interrupted);
        }
        if let Some(err) = results.into_iter().find_map(Result::err) {
            return Err(err);
        }
        written += chunk.len() as u64;
    }
    // Durable once for the whole run, then committed by its manifest.
    manifest.files = written;
    if written > 0 {
        scene_files::commit(&vdir, &manifest).map_err(|e| {
            format!(
                "cannot commit the scene files of `{}`: {e}\nhint: check free space and permissions under `--out`, then rerun the same command",
                vdir.display()
            )
        })?;
    }
    Ok(Sampled::Done(written))
}

/// Refuse, before anything is written, a run that would replace a file it would not write
/// itself: each existing file of the run's indices is compared with the scene this run
/// samples for its index. Equal bytes (a rerun, or a killed run of the same command) and a
/// file that is not JSON (a crash's leftover) are rewritten; a scene file of other bytes was
/// sampled by another run (another seed, stream, config or split), and any other JSON is a
/// rendered sample's metadata: both refused, named.
fn check_replaced(req: &Request, run: &scene_files::ScenesManifest) -> Result<(), String> {
    let found = scene_files::existing(req.out, run)?;
    let vdir = crate::layout::variant_dir(req.out, &req.config.name);
    let root = crate::dataset::files::root(&vdir)
        .map_err(|e| format!("cannot read `{}`: {e}", vdir.display()))?;
    let problems: Vec<String> = found
        .par_iter()
        .filter_map(|(index, path)| {
            let Ok(bytes) = crate::dataset::files::read(&root, path, 4 << 20) else {
                // Not a regular file, a link out, too large: never written through (the
                // atomic writer renames over it) and not a file of this run.
                return Some(format!(
                    "`{}` is not a scene file this run wrote\nhint: move it away, or pass another `--out`",
                    path.display()
                ));
            };
            let ours = sample(
                req.config,
                &SampleRequest {
                    seed: req.seed,
                    index: *index,
                    attempt: 0,
                    total: req.total,
                },
            )
            .ok()
            .and_then(|s| clevrtex_scene::to_pretty_json(&s).ok());
            if ours.as_deref().map(str::as_bytes) == Some(&bytes[..]) {
                return None;
            }
            let value: serde_json::Value = serde_json::from_slice(&bytes).ok()?;
            if value["format"] != clevrtex_scene::scene_file::SCENE_FORMAT {
                return Some(scene_files::rendered_here(&vdir, path));
            }
            let show = |k: &str| clevrtex_scene::text::printable(&value[k].to_string()).into_owned();
            Some(format!(
                "`{}` is a scene file of another run (seed {}, layout stream {}, split {}), not the one this run samples (seed {}, layout stream {}, `--total {}`): sampling here would replace it\nhint: pass another `--out` for these settings, or rerun with that run's settings",
                path.display(),
                show("seed"),
                show("layout_stream"),
                show("split"),
                run.seed,
                run.layout_stream,
                run.total
            ))
        })
        .collect();
    match problems.into_iter().next() {
        Some(p) => Err(p),
        None => Ok(()),
    }
}

/// Write one scene file with the one atomic writer, made durable with the others at the end
/// ([`scene_files`]).
fn write_scene(out: &Path, variant: &str, scene: &clevrtex_scene::SceneFile) -> Result<(), String> {
    let dir = sample_dir(out, variant, scene.index);
    let path = dir.join(format!("{}.json", scene.stem));
    let text = clevrtex_scene::to_pretty_json(scene)
        .map_err(|e| format!("cannot serialise scene: {e}"))?;
    scene_files::write(&path, text.as_bytes()).map_err(|e| {
        format!(
            "cannot write `{}`: {e}\nhint: check free space and permissions under `--out`",
            path.display()
        )
    })
}
