//! The memory a manifest costs its readers, counted by a global allocator (exact, not timed):
//! reading a manifest (`Manifest::read`), `verify` and `verify --against` of datasets whose
//! manifests hold 140,000 files are bounded by the manifests' size (issue 48: a 76 MB
//! manifest cost 2.6 GB in `--against`). One test in this binary, so nothing else allocates
//! while it counts.

use std::path::Path;

use peakmem_alloc::{PeakMemAlloc, PeakMemAllocTrait, INSTRUMENTED_SYSTEM};

#[global_allocator]
static GLOBAL: &PeakMemAlloc<std::alloc::System> = &INSTRUMENTED_SYSTEM;

/// The most bytes held at once while `f` ran, over what was held before.
fn peak_of<T>(f: impl FnOnce() -> T) -> (T, usize) {
    GLOBAL.reset_peak_memory();
    let out = f();
    (out, GLOBAL.get_peak_memory())
}

/// A finished manifest of `n` samples of 7 files each (none on disk), written as `generate`
/// writes one (pretty JSON), into `root/clevrtex_full/`; its size in bytes.
fn write_manifest(root: &Path, n: u64) -> u64 {
    let mut files = serde_json::Map::new();
    let mut seconds = serde_json::Map::new();
    for i in 0..n {
        let stem = format!("CLEVRTEX_full_{i:06}");
        let names =
            clevrtex_dataset::layout::expected_files(&stem, &clevrtex_scene::Pass::ALL, false);
        for (k, name) in names.iter().enumerate() {
            let h = (i * 7 + k as u64).wrapping_mul(0x9e37_79b9_7f4a_7c15);
            files.insert(
                format!("{}/{name}", i / 1000),
                serde_json::json!({"size": 1000 + (i * 7 + k as u64) % 5000, "xxh3": format!("{h:016x}")}),
            );
        }
        seconds.insert(stem, serde_json::json!(10.5 + (i % 7) as f64));
    }
    let m = serde_json::json!({
        "format": "clevrtex-manifest", "version": 1, "variant": "full", "seed": 0,
        "layout_stream": "full", "config_hash": "5ef28a3dd04c5cac",
        "start": 0, "end": n, "total": n, "shard": [0, 1],
        "passes": ["rgb", "mask", "depth", "normal", "albedo", "shadow"],
        "tool_version": "0.1.0", "blender_version": "3.4.1",
        "command": ["clevrtex", "generate", "--variant", "full", "-n", n.to_string()],
        "finished": true, "files": files, "sample_seconds": seconds,
    });
    let dir = root.join("clevrtex_full");
    std::fs::create_dir_all(&dir).unwrap();
    let text = serde_json::to_string_pretty(&m).unwrap();
    std::fs::write(dir.join(format!("MANIFEST-0-{n}-0of1.json")), &text).unwrap();
    text.len() as u64
}

#[test]
fn a_manifest_costs_its_readers_about_its_size() {
    let tmp = tempfile::tempdir().unwrap();
    let (a, b) = (tmp.path().join("a"), tmp.path().join("b"));
    let n = 20_000;
    let size = write_manifest(&a, n) as f64;
    write_manifest(&b, n);
    let path = a.join(format!("clevrtex_full/MANIFEST-0-{n}-0of1.json"));

    let (m, read) = peak_of(|| clevrtex_dataset::manifest::Manifest::read(&path).unwrap());
    assert_eq!(m.files.len() as u64, 7 * n);
    drop(m);
    let (reports, verify) = peak_of(|| {
        clevrtex_dataset::verify::verify(
            std::slice::from_ref(&a),
            &clevrtex_dataset::verify::VerifyOptions::default(),
        )
        .unwrap()
    });
    assert_eq!(reports[0].missing_count, n, "every sample is missing");
    drop(reports);
    let (c, against) =
        peak_of(|| clevrtex_dataset::verify::against(std::slice::from_ref(&a), &b, None).unwrap());
    assert_eq!(c[0].compared, n);
    drop(c);
    let ratio = |bytes: usize| bytes as f64 / size;
    eprintln!(
        "manifest {size} bytes; peak heap: read {:.2}x, verify {:.2}x, --against {:.2}x (both sides' manifests: {:.2}x each)",
        ratio(read),
        ratio(verify),
        ratio(against),
        ratio(against) / 2.0
    );
    assert!(
        ratio(read) <= 1.6,
        "reading a manifest held {:.2}x its size",
        ratio(read)
    );
    assert!(
        ratio(verify) <= 2.5,
        "verify held {:.2}x the manifest's size",
        ratio(verify)
    );
    assert!(
        ratio(against) <= 4.5,
        "verify --against held {:.2}x one side's manifest's size (two sides)",
        ratio(against)
    );
}
