//! Cycles CUDA kernels prepared ahead of time, without a GPU (issue 35): `scripts/cuda_kernels.py`
//! (run by `./scripts/setup.sh --bpy 4.5 --cuda-arch 80,90`) compiles the PTX that a bpy ships
//! with `ptxas` into `kernel_sm_XY.cubin.zst` in the Cycles add-on's `lib`, where Cycles loads
//! ready-made kernels first. The real PTX takes ~16 CPU-minutes; these tests run the same code
//! on a tiny PTX (`tests/data/cuda/tiny_compute_75.ptx`) in a copy of that folder's layout.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

use clevrtex_render::device::{CudaKernels, KernelLoad};

use crate::util::{blender_or_skip, data, repo_root, skip, text, REQUIRE_TOOLS};

/// `python3 scripts/cuda_kernels.py ARGS`.
fn prepare(args: &[&std::ffi::OsStr], envs: &[(&str, &std::ffi::OsStr)]) -> Output {
    let mut cmd = Command::new("python3");
    cmd.arg(repo_root().join("scripts/cuda_kernels.py"))
        .args(args);
    for (k, v) in envs {
        cmd.env(k, v);
    }
    cmd.output().expect("run python3")
}

/// A Cycles `lib` folder with the tiny PTX as `kernel_compute_75.ptx.zst` (compressed with the
/// `zstd` tool, as bpy ships its kernels) and a "shipped" cubin for sm_86.
fn fake_cycles_lib(dir: &Path) -> PathBuf {
    let lib = dir.join("cycles/lib");
    std::fs::create_dir_all(&lib).unwrap();
    let st = Command::new("zstd")
        .arg("-q")
        .arg(data("cuda/tiny_compute_75.ptx"))
        .arg("-o")
        .arg(lib.join("kernel_compute_75.ptx.zst"))
        .status()
        .expect("zstd (apt-get install zstd)");
    assert!(st.success());
    std::fs::write(lib.join("kernel_sm_86.cubin.zst"), b"shipped").unwrap();
    lib
}

/// `ptxas`: CLEVRTEX_PTXAS, on PATH, or the one `./scripts/setup.sh --ptxas` installs in
/// `.venv-cuda/`; `None` (test skipped, or failed under CLEVRTEX_REQUIRE_TOOLS=1) without one.
fn ptxas_or_skip(test: &str) -> Option<PathBuf> {
    let found = std::env::var_os("CLEVRTEX_PTXAS")
        .map(PathBuf::from)
        .or_else(|| {
            std::env::split_paths(&std::env::var_os("PATH").unwrap_or_default())
                .map(|d| d.join("ptxas"))
                .find(|p| p.is_file())
        })
        .or_else(|| {
            let lib = repo_root().join(".venv-cuda/lib");
            std::fs::read_dir(lib).ok()?.flatten().find_map(|py| {
                let p = py.path().join("site-packages/nvidia/cuda_nvcc/bin/ptxas");
                p.is_file().then_some(p)
            })
        });
    if found.is_none() {
        skip(
            test,
            REQUIRE_TOOLS,
            "ptxas not found",
            "install it with `./scripts/setup.sh --ptxas` (PyPI's nvidia-cuda-nvcc-cu12 in .venv-cuda/) or set CLEVRTEX_PTXAS",
        );
    }
    found
}

/// The ELF header of a cubin: (machine, SM from the flags' low byte).
fn cubin_arch(zst: &Path) -> (u16, u32) {
    let out = Command::new("zstd").arg("-dc").arg(zst).output().unwrap();
    assert!(out.status.success(), "{}", text(&out));
    let elf = out.stdout;
    assert_eq!(&elf[..4], b"\x7fELF", "not an ELF file: {}", zst.display());
    let machine = u16::from_le_bytes([elf[18], elf[19]]);
    let flags = u32::from_le_bytes([elf[48], elf[49], elf[50], elf[51]]);
    (machine, flags & 0xff)
}

#[test]
fn unknown_compute_capabilities_are_refused_up_front() {
    let dir = tempfile::tempdir().unwrap();
    let lib = fake_cycles_lib(dir.path());
    let o = prepare(
        &[
            "--cuda-arch".as_ref(),
            "80,99".as_ref(),
            "--cycles-lib".as_ref(),
            lib.as_os_str(),
        ],
        &[],
    );
    assert_eq!(o.status.code(), Some(2), "{}", text(&o));
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(
        err.starts_with(
            "error: `--cuda-arch 99` is not a CUDA compute capability ptxas can build for\nhint: "
        ),
        "{err}"
    );
    assert!(!lib.join("kernel_sm_80.cubin.zst").exists());
    // setup.sh refuses it before installing anything.
    let o = Command::new("bash")
        .arg(repo_root().join("scripts/setup.sh"))
        .args(["--cuda-arch", "99"])
        .output()
        .unwrap();
    assert_eq!(o.status.code(), Some(2), "{}", text(&o));
    assert!(
        text(&o).contains("`--cuda-arch 99` is not a CUDA compute capability"),
        "{}",
        text(&o)
    );
}

#[test]
fn no_network_for_the_compiler_package_is_a_clear_error() {
    let dir = tempfile::tempdir().unwrap();
    let lib = fake_cycles_lib(dir.path());
    let venv = dir.path().join("venv-cuda");
    // No ptxas on PATH, and an index nobody answers on.
    let o = prepare(
        &[
            "--cuda-arch".as_ref(),
            "90".as_ref(),
            "--cycles-lib".as_ref(),
            lib.as_os_str(),
            "--cuda-venv".as_ref(),
            venv.as_os_str(),
        ],
        &[
            ("PATH", "/usr/bin:/bin".as_ref()),
            ("PIP_INDEX_URL", "http://127.0.0.1:9/simple".as_ref()),
            ("PIP_NO_CACHE_DIR", "1".as_ref()),
        ],
    );
    if String::from_utf8_lossy(&o.stdout).contains("ptxas:") || Path::new("/usr/bin/ptxas").exists()
    {
        return; // a CUDA toolkit in /usr/bin: nothing to install
    }
    assert_eq!(o.status.code(), Some(1), "{}", text(&o));
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(
        err.contains("error: cannot install `nvidia-cuda-nvcc-cu12` from PyPI, which has the `ptxas` compiler")
            && err.contains("\nhint: this needs network access to PyPI once"),
        "{err}"
    );
    assert!(!lib.join("kernel_sm_90.cubin.zst").exists());
}

#[test]
fn prepared_kernels_are_built_named_and_found_as_cycles_looks_for_them() {
    let test = "gpu_kernels::prepared_kernels_are_built_named_and_found_as_cycles_looks_for_them";
    let Some(ptxas) = ptxas_or_skip(test) else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let lib = fake_cycles_lib(dir.path());
    let args = |archs: &str| -> Vec<std::ffi::OsString> {
        vec![
            "--cuda-arch".into(),
            archs.into(),
            "--cycles-lib".into(),
            lib.clone().into(),
            "--ptxas".into(),
            ptxas.clone().into(),
        ]
    };
    let run = |archs: &str| {
        let a = args(archs);
        let refs: Vec<&std::ffi::OsStr> = a.iter().map(|s| s.as_os_str()).collect();
        prepare(&refs, &[])
    };
    let o = run("8.0,sm_90,86");
    assert_eq!(o.status.code(), Some(0), "{}", text(&o));
    let t = text(&o);
    assert!(t.contains("sm_86: shipped with this Blender"), "{t}");
    // Built for the right GPU generation, under the name Cycles looks for first.
    const EM_CUDA: u16 = 190;
    for sm in [80, 90] {
        let file = lib.join(format!("kernel_sm_{sm}.cubin.zst"));
        assert_eq!(cubin_arch(&file), (EM_CUDA, sm), "{}", file.display());
    }
    assert_eq!(
        std::fs::read(lib.join("kernel_sm_86.cubin.zst")).unwrap(),
        b"shipped"
    );
    // Run again: nothing to compile.
    let o = run("80,90");
    assert_eq!(o.status.code(), Some(0), "{}", text(&o));
    assert!(
        text(&o).contains("sm_90: prepared before from kernel_compute_75.ptx.zst"),
        "{}",
        text(&o)
    );
    // The bridge, in a real Blender, lists them as cubins and as prepared: `doctor` says
    // "prepared", and no worker is given the kernel-compile grace.
    let Some(blender) = blender_or_skip(test) else {
        return;
    };
    let script = dir.path().join("kernels.py");
    std::fs::write(
        &script,
        format!(
            "import json, sys\nsys.path.insert(0, {root:?})\nimport bpy\nimport compat\nprint('KERNELS ' + json.dumps(compat.cuda_kernels({lib:?})))\n",
            root = repo_root().join("blender_scripts").to_string_lossy(),
            lib = lib.to_string_lossy()
        ),
    )
    .unwrap();
    let flavour = clevrtex_render::blender::flavour(&blender);
    let out = clevrtex_render::blender::worker_command(&blender, flavour, &script, &[])
        .output()
        .unwrap();
    let t = text(&out);
    assert!(out.status.success(), "{t}");
    let line = String::from_utf8_lossy(&out.stdout)
        .lines()
        .find_map(|l| l.strip_prefix("KERNELS ").map(str::to_string))
        .unwrap_or_else(|| panic!("{t}"));
    let k: CudaKernels = serde_json::from_str(&line).unwrap();
    assert_eq!(
        k,
        CudaKernels {
            cubin: vec![80, 86, 90],
            ptx: vec![75],
            prepared: vec![80, 90],
        }
    );
    assert_eq!(k.load_for(90), KernelLoad::Prepared);
    assert_eq!(k.load_for(86), KernelLoad::Shipped);
    assert_eq!(k.load_for(89), KernelLoad::Compiled { from: 75 });
}

/// `scripts/gpu_check.sh` needs an NVIDIA GPU: without one it says so and exits 1 before
/// building or rendering anything.
#[test]
fn gpu_check_refuses_clearly_without_a_gpu() {
    let dir = tempfile::tempdir().unwrap();
    let o = Command::new("bash")
        .arg(repo_root().join("scripts/gpu_check.sh"))
        .arg(dir.path().join("work"))
        .env("NVIDIA_SMI", "false")
        .output()
        .unwrap();
    assert_eq!(o.status.code(), Some(1), "{}", text(&o));
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(
        err.starts_with(
            "error: no NVIDIA GPU here (`false` lists none), so there is nothing to check\nhint: "
        ),
        "{err}"
    );
    assert!(!dir.path().join("work").exists());
}

/// The comparison step of `scripts/gpu_check.sh` (`scripts/gpu_compare.py`), on datasets made
/// here with known noise: a "GPU" render as noisy as the CPU's full-sample one passes; one 10
/// levels brighter, or with one mask byte changed, fails; a missing run is bad input.
#[test]
fn gpu_comparison_passes_noise_and_catches_bias_and_mask_changes() {
    let Some(python) = crate::util::test_python_or_skip("gpu_comparison", "PIL") else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let make = r#"
import os, sys
import numpy as np
from PIL import Image
root = sys.argv[1]
truth = np.fromfunction(lambda y, x, c: 40 + x * 2 + y + c * 20, (24, 32, 3))
mask = (np.arange(24 * 32).reshape(24, 32) % 3).astype(np.uint8)
def write(name, sigma, seed, bias=0.0, mask_flip=False):
    rng = np.random.default_rng(seed)
    for i in range(2):
        d = os.path.join(root, name, "clevrtex_clevr", "0")
        os.makedirs(d, exist_ok=True)
        stem = "CLEVRTEX_clevr_%06d" % i
        img = np.clip(truth + bias + rng.normal(0, sigma, truth.shape), 0, 255).astype(np.uint8)
        Image.fromarray(img).save(os.path.join(d, stem + ".png"))
        m = mask.copy()
        if mask_flip and i == 1:
            m[3, 4] ^= 1
        Image.fromarray(m).save(os.path.join(d, stem + "_flat.png"))
        open(os.path.join(d, stem + ".json"), "w").write("{}")
write("cpu", 4, 1)
write("cpu16", 8, 2)
write("gpu", 4, 3)
write("gpu_bright", 4, 3, bias=10)
write("gpu_mask", 4, 3, mask_flip=True)
"#;
    let o = Command::new(&python)
        .args(["-c", make])
        .arg(dir.path())
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", text(&o));
    let compare = |gpu: &str| {
        Command::new(&python)
            .arg(repo_root().join("scripts/gpu_compare.py"))
            .arg("--gpu")
            .arg(dir.path().join(gpu))
            .arg("--cpu")
            .arg(dir.path().join("cpu"))
            .arg("--cpu-low")
            .arg(dir.path().join("cpu16"))
            .arg("clevr")
            .output()
            .unwrap()
    };
    let o = compare("gpu");
    assert_eq!(o.status.code(), Some(0), "{}", text(&o));
    assert!(
        text(&o).contains("compared 2 image(s): 2 ok, 0 failed"),
        "{}",
        text(&o)
    );
    let o = compare("gpu_bright");
    assert_eq!(o.status.code(), Some(1), "{}", text(&o));
    assert!(
        text(&o).contains("RGB differs by more than the CPU's own noise"),
        "{}",
        text(&o)
    );
    let o = compare("gpu_mask");
    assert_eq!(o.status.code(), Some(1), "{}", text(&o));
    assert!(
        text(&o).contains("CLEVRTEX_clevr_000001: mask DIFFERENT")
            && text(&o).contains("1 ok, 1 failed"),
        "{}",
        text(&o)
    );
    let o = compare("no_such_run");
    assert_eq!(o.status.code(), Some(2), "{}", text(&o));
    assert!(
        text(&o)
            .contains("error: `CLEVRTEX_clevr_000000` is in the CPU run but not in the GPU run"),
        "{}",
        text(&o)
    );
}

/// Issue 42, minor: `setup.sh --cuda-arch 80,,90` (also `,80`, `80,`, `" 80"`) passed the
/// up-front check, and `--cuda-arch` without `--bpy` (and no `.venv-bpy`) was refused only
/// after the apt step. Both are refused first (exit 2), before anything is installed: run
/// from a copy of `scripts/` in an empty folder, so no `.venv-bpy` of this checkout counts.
#[test]
fn setup_refuses_a_malformed_cuda_arch_list_and_cuda_arch_without_bpy_up_front() {
    let dir = tempfile::tempdir().unwrap();
    let scripts = dir.path().join("scripts");
    std::fs::create_dir_all(&scripts).unwrap();
    for f in ["setup.sh", "cuda_kernels.py"] {
        std::fs::copy(repo_root().join("scripts").join(f), scripts.join(f)).unwrap();
    }
    let setup = |args: &[&str]| {
        Command::new("bash")
            .arg(scripts.join("setup.sh"))
            .args(args)
            .output()
            .unwrap()
    };
    for (list, what) in [
        ("80,,90", "has an empty entry"),
        (",80", "has an empty entry"),
        ("80,", "has an empty entry"),
        (" 80", "has an entry with spaces (` 80`)"),
    ] {
        let o = setup(&["--bpy", "4.5", "--cuda-arch", list]);
        assert_eq!(o.status.code(), Some(2), "{list:?}: {}", text(&o));
        assert!(text(&o).contains(what), "{list:?}: {}", text(&o));
    }
    let o = setup(&["--cuda-arch", "80"]);
    assert_eq!(o.status.code(), Some(2), "{}", text(&o));
    let t = text(&o);
    assert!(
        t.contains(
            "`--cuda-arch` prepares the kernels of PyPI's bpy, and there is none in .venv-bpy"
        ) && t.contains("hint: add `--bpy 4.5`"),
        "{t}"
    );
    assert!(!t.contains("apt"), "refused after the apt step: {t}");
}
