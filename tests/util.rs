//! Helpers shared by the integration tests.
#![allow(dead_code)]

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

/// The `clevrtex` binary under test.
pub fn clevrtex() -> Command {
    Command::new(env!("CARGO_BIN_EXE_clevrtex"))
}

/// Run `clevrtex` with `args`, returning its output.
pub fn run(args: &[&str]) -> Output {
    clevrtex()
        .args(args)
        .output()
        .expect("failed to start clevrtex")
}

/// Stdout and stderr as text, for assertion messages.
pub fn text(out: &Output) -> String {
    format!(
        "status: {:?}\n--- stdout\n{}\n--- stderr\n{}",
        out.status.code(),
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    )
}

/// Path of the repository root.
pub fn repo_root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

/// Path of a fixture under `tests/data/`.
pub fn data(rel: &str) -> PathBuf {
    repo_root().join("tests/data").join(rel)
}

/// The variable that turns every skip of a missing external tool (Blender, the test Python
/// and its libraries, Chromium, SLURM) into a failure; `.ci/run` sets it.
/// `CLEVRTEX_REQUIRE_BLENDER=1`, its old name, is still honoured.
pub const REQUIRE_TOOLS: &str = "CLEVRTEX_REQUIRE_TOOLS";

/// The variable that makes the bpy half of the real-render tests required.
pub const REQUIRE_BPY: &str = "CLEVRTEX_REQUIRE_BPY";

/// Whether `var` (one of [`REQUIRE_TOOLS`], [`REQUIRE_BPY`]) is set to 1.
pub fn required(var: &str) -> bool {
    let set = |v: &str| std::env::var(v).as_deref() == Ok("1");
    set(var) || (var == REQUIRE_TOOLS && set("CLEVRTEX_REQUIRE_BLENDER"))
}

/// Skip `test` because `missing` is absent (`fix` says how to get it), or fail when `var`
/// makes it required.
///
/// A skip is printed on stderr and, when `CLEVRTEX_SKIP_LOG` names a file (the README's test
/// command, `scripts/test.sh`, sets it), appended to it as one line, so that the test
/// command's summary lists every skipped test: cargo's harness hides a passing test's stderr
/// and has no "skipped" of its own.
pub fn skip(test: &str, var: &str, missing: &str, fix: &str) {
    if required(var) {
        panic!("{test}: {missing}, but it is required ({var}=1); {fix}");
    }
    let line = format!("{test} ({missing}; {fix}; {var}=1 makes this a failure)");
    eprintln!("SKIPPED {line}");
    if let Some(log) = std::env::var_os("CLEVRTEX_SKIP_LOG") {
        use std::io::Write;
        let mut f = std::fs::OpenOptions::new()
            .create(true)
            .append(true)
            .open(&log)
            .unwrap_or_else(|e| panic!("CLEVRTEX_SKIP_LOG {}: {e}", Path::new(&log).display()));
        // One write of one line: lines of parallel tests do not interleave.
        f.write_all(format!("{line}\n").as_bytes()).unwrap();
    }
}

/// The Blender binary to use for real-render tests, or `None` to skip the test.
///
/// Looks at `CLEVRTEX_BLENDER`, then `blender` on `PATH`. When Blender is absent the test is
/// skipped visibly ([`skip`]), unless [`REQUIRE_TOOLS`] makes it required (CI sets it, so a
/// missing Blender fails CI instead of skipping).
pub fn blender_or_skip(test: &str) -> Option<PathBuf> {
    let candidate = std::env::var_os("CLEVRTEX_BLENDER")
        .map(PathBuf::from)
        .or_else(|| find_on_path("blender"));
    match candidate {
        Some(p) if p.exists() => Some(p),
        _ => {
            skip(
                test,
                REQUIRE_TOOLS,
                "Blender not found",
                "install it with `apt-get install -y blender` or set CLEVRTEX_BLENDER",
            );
            None
        }
    }
}

/// A Python interpreter that imports PyPI's `bpy` (the second Blender of the real-render
/// tests), or `None` to skip the bpy half of a test.
///
/// Looks at `CLEVRTEX_TEST_BPY`, then the project's `.venv-bpy/bin/python` (made by
/// `./scripts/setup.sh --bpy 4.5`). When absent the bpy half is skipped visibly, unless
/// [`REQUIRE_BPY`] (set by `.ci/run`) makes it required.
pub fn bpy_or_skip(test: &str) -> Option<PathBuf> {
    let candidate = std::env::var_os("CLEVRTEX_TEST_BPY")
        .map(PathBuf::from)
        .unwrap_or_else(|| repo_root().join(".venv-bpy/bin/python"));
    if candidate.exists() {
        return Some(candidate);
    }
    skip(
        &format!("{test} on bpy"),
        REQUIRE_BPY,
        &format!("no `{}`", candidate.display()),
        "run `./scripts/setup.sh --bpy 4.5` or set CLEVRTEX_TEST_BPY",
    );
    None
}

/// Every Blender a real-render test runs on: [`blender_or_skip`]'s, then [`bpy_or_skip`]'s
/// (each may be absent, with its visible skip or its required failure).
pub fn test_blenders(test: &str) -> Vec<PathBuf> {
    blender_or_skip(test)
        .into_iter()
        .chain(bpy_or_skip(test))
        .collect()
}

fn find_on_path(name: &str) -> Option<PathBuf> {
    let path = std::env::var_os("PATH")?;
    std::env::split_paths(&path)
        .map(|dir| dir.join(name))
        .find(|p| is_file(p))
}

fn is_file(p: &Path) -> bool {
    p.is_file()
}

/// A Python interpreter with the libraries the format round-trip tests read our files with
/// (`webdataset`): `CLEVRTEX_TEST_PYTHON`, else the `.venv-test` that `.ci/run` (and
/// `scripts/setup.sh --test-venv`) makes. `None` (a visible skip) when absent, unless
/// [`REQUIRE_TOOLS`] makes it required.
pub fn test_python_or_skip(test: &str, module: &str) -> Option<PathBuf> {
    let candidate = std::env::var_os("CLEVRTEX_TEST_PYTHON")
        .map(PathBuf::from)
        .unwrap_or_else(|| repo_root().join(".venv-test/bin/python"));
    let ok = std::process::Command::new(&candidate)
        .args(["-c", &format!("import {module}")])
        .output()
        .is_ok_and(|o| o.status.success());
    if ok {
        return Some(candidate);
    }
    skip(
        test,
        REQUIRE_TOOLS,
        &format!(
            "no Python with `{module}` (`{}` cannot import it)",
            candidate.display()
        ),
        if module.contains("torch") {
            "run `./scripts/setup.sh --torch` or set CLEVRTEX_TEST_PYTHON"
        } else {
            "run `./scripts/setup.sh --test-venv` or set CLEVRTEX_TEST_PYTHON"
        },
    );
    None
}

/// A headless Chromium for the report's browser test: `CLEVRTEX_CHROMIUM`, else `chromium`
/// (Debian's package) or `chromium-browser` on `PATH`. `None` (a visible skip) when absent,
/// unless [`REQUIRE_TOOLS`] makes it required.
pub fn chromium_or_skip(test: &str) -> Option<PathBuf> {
    let candidate = std::env::var_os("CLEVRTEX_CHROMIUM")
        .map(PathBuf::from)
        .or_else(|| find_on_path("chromium"))
        .or_else(|| find_on_path("chromium-browser"));
    match candidate {
        Some(p) if p.exists() => Some(p),
        _ => {
            skip(
                test,
                REQUIRE_TOOLS,
                "Chromium not found",
                "run `./scripts/setup.sh --browser` or set CLEVRTEX_CHROMIUM",
            );
            None
        }
    }
}

/// `clevrtex args` with at most 2 GB of address space (a file or a program that makes it
/// allocate more aborts it), with `envs` set, killed (a test failure) after `secs`; its exit
/// code (`None`: killed by a signal, e.g. SIGABRT on an allocation failure) and
/// [`text`].
pub fn run_limited(
    args: &[&std::ffi::OsStr],
    envs: &[(&str, &std::ffi::OsStr)],
    secs: u64,
) -> (Option<i32>, String) {
    let mut cmd = Command::new("sh");
    cmd.args(["-c", "ulimit -v 2000000; exec \"$0\" \"$@\""])
        .arg(env!("CARGO_BIN_EXE_clevrtex"))
        .args(args)
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped());
    for (k, v) in envs {
        cmd.env(k, v);
    }
    let mut child = cmd.spawn().unwrap();
    let t = std::time::Instant::now();
    while child.try_wait().unwrap().is_none() {
        if t.elapsed().as_secs() > secs {
            child.kill().unwrap();
            let o = child.wait_with_output().unwrap();
            panic!(
                "clevrtex {args:?} still running after {secs} s:\n{}",
                text(&o)
            );
        }
        std::thread::sleep(std::time::Duration::from_millis(100));
    }
    let o = child.wait_with_output().unwrap();
    (o.status.code(), text(&o))
}

/// The fake Blender of `tests/fake_blender/` (its modes are listed at its top).
pub fn fake_blender() -> PathBuf {
    repo_root().join("tests/fake_blender/blender")
}

/// An executable `blender` in `dir` that runs `body` (a `sh` script; `"$@"` holds Blender's
/// arguments), e.g. to pick the fake's mode per start without touching this process's
/// environment.
pub fn blender_wrapper(dir: &Path, body: &str) -> PathBuf {
    use std::os::unix::fs::PermissionsExt;
    let path = dir.join("blender");
    std::fs::write(&path, format!("#!/bin/sh\n{body}\n")).unwrap();
    std::fs::set_permissions(&path, std::fs::Permissions::from_mode(0o755)).unwrap();
    path
}

/// A [`blender_wrapper`] whose first start is the fake Blender in `crash` mode (dies on its
/// first request) and whose later starts run `then` (a program, given Blender's arguments;
/// the marker file in `dir` remembers the first start).
pub fn crash_once_then(dir: &Path, then: &str) -> PathBuf {
    let marker = dir.join("crashed-once");
    blender_wrapper(
        dir,
        &format!(
            "if [ ! -e '{marker}' ]; then\n  : > '{marker}'\n  FAKE_BLENDER_MODE=crash exec '{fake}' \"$@\"\nfi\nexec {then} \"$@\"",
            marker = marker.display(),
            fake = fake_blender().display(),
        ),
    )
}

/// Two copies of one sample file made by different runs of the same seed: masks, depth and
/// metadata byte-equal; the RGB image of the same size with at most 1% of its values
/// different (Cycles is not bit-reproducible under every load; see docs/scene-format.md).
pub fn assert_same_sample_file(name: &str, a: &[u8], b: &[u8]) {
    let is_rgb = name.ends_with(".png")
        && !name[..name.len() - 4].contains("_0001")
        && !name.ends_with("_flat.png");
    if !is_rgb {
        assert!(a == b, "{name} differs between the runs");
        return;
    }
    if a == b {
        return;
    }
    let (ia, ib) = (
        image::load_from_memory(a).unwrap().to_rgb8(),
        image::load_from_memory(b).unwrap().to_rgb8(),
    );
    assert_eq!(ia.dimensions(), ib.dimensions(), "{name}");
    let diffs: Vec<u8> = ia
        .as_raw()
        .iter()
        .zip(ib.as_raw())
        .map(|(x, y)| x.abs_diff(*y))
        .filter(|d| *d > 0)
        .collect();
    let max = diffs.iter().copied().max().unwrap_or(0);
    assert!(
        diffs.len() * 100 <= ia.as_raw().len(),
        "{name}: {} of {} values differ, by up to {max}",
        diffs.len(),
        ia.as_raw().len()
    );
    eprintln!(
        "note: {name}: {} of {} RGB values differ between the runs, by up to {max}",
        diffs.len(),
        ia.as_raw().len()
    );
}

/// Copy `variant` of our dataset into the published layout: the same files, metadata with
/// only the published keys, no manifest.
pub fn published_copy(ours: &Path, variant: &str, dst: &Path) {
    let sub = dst.join(format!("clevrtex_{variant}/0"));
    std::fs::create_dir_all(&sub).unwrap();
    for e in std::fs::read_dir(ours.join(format!("clevrtex_{variant}/0")))
        .unwrap()
        .flatten()
    {
        let name = e.file_name().to_string_lossy().into_owned();
        if name.ends_with(".json") {
            let mut meta: serde_json::Value =
                serde_json::from_slice(&std::fs::read(e.path()).unwrap()).unwrap();
            let keep = [
                "num_objects",
                "split",
                "image_index",
                "image_filename",
                "ground_material",
                "directions",
                "objects",
                "relationships",
                "mask_filename",
                "depth_filename",
            ];
            meta.as_object_mut()
                .unwrap()
                .retain(|k, _| keep.contains(&k.as_str()));
            for o in meta["objects"].as_array_mut().unwrap() {
                o.as_object_mut()
                    .unwrap()
                    .retain(|k, _| k != "visible_pixels" && k != "bbox");
            }
            std::fs::write(sub.join(&name), meta.to_string()).unwrap();
        } else {
            std::fs::copy(e.path(), sub.join(&name)).unwrap();
        }
    }
}

/// A hand-made sample of `variant` in the published layout under `out`: metadata with no
/// objects, an RGB PNG of `rgb` size and a grey mask PNG of `mask` size (0 everywhere), for
/// tests of what readers do with files no renderer would write.
pub fn hand_png_sample(out: &Path, variant: &str, index: u64, rgb: (u32, u32), mask: (u32, u32)) {
    let sub = out.join(format!("clevrtex_{variant}/{}", index / 1000));
    std::fs::create_dir_all(&sub).unwrap();
    let stem = format!("CLEVRTEX_{variant}_{index:06}");
    let meta = serde_json::json!({
        "image_index": index, "variant": variant, "split": "test", "num_objects": 0,
        "objects": [], "ground_material": "plain",
    });
    std::fs::write(sub.join(format!("{stem}.json")), meta.to_string()).unwrap();
    image::RgbImage::from_pixel(rgb.0, rgb.1, image::Rgb([90, 120, 150]))
        .save(sub.join(format!("{stem}.png")))
        .unwrap();
    image::GrayImage::new(mask.0, mask.1)
        .save(sub.join(format!("{stem}_flat.png")))
        .unwrap();
}

/// Run `clevrtex args`, killed (a test failure) after `secs`: for inputs that could hang a
/// command (a FIFO in a dataset).
pub fn run_within(args: &[&std::ffi::OsStr], secs: u64) -> Output {
    let mut child = clevrtex()
        .args(args)
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    let t = std::time::Instant::now();
    while child.try_wait().unwrap().is_none() {
        if t.elapsed().as_secs() > secs {
            child.kill().unwrap();
            let o = child.wait_with_output().unwrap();
            panic!(
                "clevrtex {args:?} still running after {secs} s:\n{}",
                text(&o)
            );
        }
        std::thread::sleep(std::time::Duration::from_millis(100));
    }
    child.wait_with_output().unwrap()
}

/// The two PBR texture-folder layouts `--materials DIR` reads (docs/materials.md).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum PbrLayout {
    /// `<slug>_diff_1k.jpg`, `_nor_gl_1k.png`, `_arm_1k.jpg`, `_disp_1k.png`.
    PolyHaven,
    /// `<Name>_1K-JPG_Color.jpg`, `_NormalDX.jpg`, `_Roughness.jpg`, `_Displacement.jpg`.
    AmbientCg,
}

/// Write a `w` x `h` image map of `channels` (1 grey, 3 RGB) filled with `value` (its
/// format from the extension of `path`: `.jpg` or `.png`).
pub fn pbr_map(path: &Path, w: u32, h: u32, value: &[u8]) {
    let img = match value.len() {
        1 => image::DynamicImage::ImageLuma8(image::GrayImage::from_pixel(
            w,
            h,
            image::Luma([value[0]]),
        )),
        3 => image::DynamicImage::ImageRgb8(image::RgbImage::from_pixel(
            w,
            h,
            image::Rgb([value[0], value[1], value[2]]),
        )),
        n => panic!("pbr_map: {n} channels"),
    };
    img.save(path)
        .unwrap_or_else(|e| panic!("writing {}: {e}", path.display()));
}

/// Build the PBR texture folder `parent/folder` in `layout`, 32 x 32 maps at a nominal 1K:
/// a colour map of the uniform sRGB colour `rgb`, a flat normal map (Poly Haven: OpenGL,
/// ambientCG: DirectX), roughness (Poly Haven: packed in an ARM map) and a displacement
/// map. Returns the folder; it is material `<folder lowercased>` of `--materials parent`.
pub fn pbr_folder(parent: &Path, folder: &str, layout: PbrLayout, rgb: [u8; 3]) -> PathBuf {
    let dir = parent.join(folder);
    std::fs::create_dir_all(&dir).unwrap();
    let flat = [128, 128, 255];
    match layout {
        PbrLayout::PolyHaven => {
            let f = |map: &str, ext: &str| dir.join(format!("test_slug_{map}_1k.{ext}"));
            pbr_map(&f("diff", "jpg"), 32, 32, &rgb);
            pbr_map(&f("nor_gl", "png"), 32, 32, &flat);
            pbr_map(&f("arm", "jpg"), 32, 32, &[255, 140, 0]);
            pbr_map(&f("disp", "png"), 32, 32, &[128]);
        }
        PbrLayout::AmbientCg => {
            let f = |map: &str| dir.join(format!("Test001_1K-JPG_{map}.jpg"));
            pbr_map(&f("Color"), 32, 32, &rgb);
            pbr_map(&f("NormalDX"), 32, 32, &flat);
            pbr_map(&f("Roughness"), 32, 32, &[150]);
            pbr_map(&f("Displacement"), 32, 32, &[128]);
        }
    }
    dir
}
