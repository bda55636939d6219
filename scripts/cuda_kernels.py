#!/usr/bin/env python3
"""Prepare the Cycles CUDA kernels that an installed bpy lacks, before any GPU is used.

PyPI's bpy 4.5 ships ready-made CUDA kernels (`kernel_sm_XY.cubin.zst`) for some compute
capabilities only (not 8.0, A100, nor 9.0, H100/H200) and one PTX (`kernel_compute_75.ptx.zst`).
For a GPU without its cubin, Cycles hands the nearest older PTX to the driver, which compiles
it at the first render of every worker process (15.7 CPU-minutes for sm_90, issue 35). This
script does that compile once, ahead of time, with `ptxas` from PyPI's CUDA compiler package
(`nvidia-cuda-nvcc-cu12`), and installs the result where and as Cycles looks for a ready-made
kernel first (`<cycles add-on>/lib/kernel_sm_XY.cubin.zst`), so no worker compiles at run time.
It needs no GPU. What it made is listed in `lib/clevrtex-prepared.json`, which the bridge's
`compat.cuda_kernels()` reads so that `clevrtex doctor` can say "prepared".

    python3 scripts/cuda_kernels.py --cuda-arch 80,90 [--bpy-python .venv-bpy/bin/python]
        [--cycles-lib DIR] [--ptxas PATH] [--cuda-venv .venv-cuda] [--jobs N]

Exit codes: 0 done (or nothing to do), 1 error (no bpy, no PTX, no compiler, compile failed),
2 usage error (e.g. `--cuda-arch 99`).
"""

import argparse
import concurrent.futures
import glob
import hashlib
import json
import os
import re
import shutil
import subprocess
import sys
import tempfile
import time

# Compute capabilities ptxas (CUDA 12) can make code for, as 10 x major + minor.
KNOWN = (50, 52, 53, 60, 61, 62, 70, 72, 75, 80, 86, 87, 89, 90, 100, 101, 103, 120, 121)
GPUS = {80: "A100", 86: "A10/A40/RTX 30", 89: "L4/L40/RTX 40", 90: "H100/H200", 120: "RTX 50"}
PACKAGE = "nvidia-cuda-nvcc-cu12"
MANIFEST = "clevrtex-prepared.json"


class Refused(Exception):
    """An error the user can fix: message and hint, exit 1 (or `code`)."""

    def __init__(self, message, hint, code=1):
        super().__init__(message)
        self.hint = hint
        self.code = code


def parse_archs(text):
    """`80,90`, `8.0,9.0` or `sm_80,sm_90` -> [80, 90]; anything else is refused (exit 2)."""
    out = []
    if not text.strip():
        raise Refused("`--cuda-arch` is empty", "hint: e.g. `--cuda-arch 80,90`", code=2)
    for tok in text.split(","):
        # Every entry as given: an empty one (`80,,90`, `,80`, `80,`) or one with spaces
        # (`" 80"`) is a typo, refused like any other, not passed over.
        if not tok or tok != tok.strip():
            raise Refused(
                f"`--cuda-arch {text}` has an empty entry" if not tok
                else f"`--cuda-arch {text}` has an entry with spaces (`{tok}`)",
                "hint: pass compute capabilities separated by commas alone, e.g. `--cuda-arch 80,90`",
                code=2,
            )
        m = re.fullmatch(r"(?:sm_|compute_)?(\d{1,2})(?:\.(\d))?", tok)
        cc = None
        if m:
            cc = int(m.group(1)) * 10 + int(m.group(2)) if m.group(2) else int(m.group(1))
        if cc not in KNOWN:
            known = ", ".join(f"{c}" + (f" ({GPUS[c]})" if c in GPUS else "") for c in KNOWN)
            raise Refused(
                f"`--cuda-arch {tok}` is not a CUDA compute capability ptxas can build for",
                f"hint: pass compute capabilities as 10 x major + minor, e.g. `--cuda-arch 80,90`; "
                f"known: {known}; `nvidia-smi --query-gpu=name,compute_cap --format=csv` tells a GPU's",
                code=2,
            )
        if cc not in out:
            out.append(cc)
    if not out:
        raise Refused("`--cuda-arch` is empty", "hint: e.g. `--cuda-arch 80,90`", code=2)
    return out


def cycles_lib_of(bpy_python):
    """The Cycles add-on's `lib` folder of the bpy that `bpy_python` imports (found without
    importing bpy: the package's folder, `<version>/scripts/addons*/cycles/lib`)."""
    if not (os.path.isfile(bpy_python) and os.access(bpy_python, os.X_OK)):
        raise Refused(
            f"no Python with bpy at `{bpy_python}`",
            "hint: install bpy first (`./scripts/setup.sh --bpy 4.5`), or pass `--bpy-python PATH` or `--cycles-lib DIR`",
        )
    code = "import importlib.util, os; s = importlib.util.find_spec('bpy'); print(os.path.dirname(s.origin) if s else '')"
    r = subprocess.run([bpy_python, "-c", code], capture_output=True, text=True)
    root = r.stdout.strip()
    libs = sorted(glob.glob(os.path.join(root, "*", "scripts", "addons*", "cycles", "lib"))) if root else []
    if r.returncode != 0 or not libs:
        raise Refused(
            f"`{bpy_python}` has no bpy with a Cycles add-on",
            "hint: install bpy first (`./scripts/setup.sh --bpy 4.5`), or pass `--cycles-lib DIR`",
        )
    return libs[-1]


def kernels_in(lib, kind):
    """Compute capabilities of `kernel_sm_XY.cubin.zst` (kind `cubin`) or
    `kernel_compute_XY.ptx.zst` (kind `ptx`) files in `lib` (as `compat.cuda_kernels`)."""
    pat = r"kernel_sm_(\d+)\.cubin(\.zst)?" if kind == "cubin" else r"kernel_compute_(\d+)\.ptx(\.zst)?"
    out = {}
    for name in os.listdir(lib):
        m = re.fullmatch(pat, name)
        if m:
            out[int(m.group(1))] = name
    return out


def read_manifest(lib):
    try:
        with open(os.path.join(lib, MANIFEST)) as f:
            doc = json.load(f)
        return {int(k["sm"]): k for k in doc.get("kernels", []) if isinstance(k, dict) and "sm" in k}
    except (OSError, ValueError, TypeError, KeyError):
        return {}


def write_atomic(path, data):
    """Write `data` to `path` through a fresh temporary file beside it, renamed over it."""
    fd, tmp = tempfile.mkstemp(prefix=".clevrtex-", dir=os.path.dirname(path))
    try:
        with os.fdopen(fd, "wb") as f:
            f.write(data)
        os.replace(tmp, path)
    except BaseException:
        if os.path.exists(tmp):
            os.unlink(tmp)
        raise


def find_ptxas(args):
    """`--ptxas`, else `ptxas` on PATH, else the one of PACKAGE in `--cuda-venv` (installed
    there from PyPI when missing)."""
    if args.ptxas:
        if not (os.path.isfile(args.ptxas) and os.access(args.ptxas, os.X_OK)):
            raise Refused(f"`--ptxas {args.ptxas}` is not an executable", "hint: pass the path of CUDA's `ptxas`")
        return args.ptxas
    on_path = shutil.which("ptxas")
    if on_path:
        return on_path
    venv = args.cuda_venv
    pattern = os.path.join(venv, "lib", "python3*", "site-packages", "nvidia", "cuda_nvcc", "bin", "ptxas")
    found = glob.glob(pattern)
    if not found:
        print(f"cuda kernels: installing `{PACKAGE}` (ptxas) from PyPI into `{venv}`", flush=True)
        if not os.path.exists(os.path.join(venv, "bin", "pip")):
            r = subprocess.run([sys.executable, "-m", "venv", venv], capture_output=True, text=True)
            if r.returncode != 0:
                raise Refused(f"cannot make the venv `{venv}`: {r.stderr.strip()[-300:]}",
                              "hint: install python3-venv (`apt-get install python3-venv`)")
        r = subprocess.run(
            [os.path.join(venv, "bin", "pip"), "install", "--quiet", "--disable-pip-version-check",
             "--timeout", "30", "--retries", "1", PACKAGE],
            capture_output=True, text=True)
        found = glob.glob(pattern)
        if r.returncode != 0 or not found:
            last = (r.stderr.strip().splitlines() or ["no output"])[-1]
            raise Refused(
                f"cannot install `{PACKAGE}` from PyPI, which has the `ptxas` compiler ({last})",
                "hint: this needs network access to PyPI once; or install the CUDA toolkit and pass "
                "`--ptxas PATH`, or `pip download nvidia-cuda-nvcc-cu12` where there is network and "
                f"`{venv}/bin/pip install` the wheel here")
    return found[0]


def decompress(src, dst):
    if src.endswith(".zst"):
        r = subprocess.run(["zstd", "-q", "-d", "-f", src, "-o", dst], capture_output=True, text=True)
        if r.returncode != 0:
            raise Refused(f"cannot decompress `{src}`: {r.stderr.strip()}", "hint: install zstd (`apt-get install zstd`)")
    else:
        shutil.copyfile(src, dst)


def prepare_one(lib, ptxas, sm, ptx_name, ptxas_version):
    """Compile `ptx_name` of `lib` for `sm` and install it as `kernel_sm_<sm>.cubin.zst`."""
    src = os.path.join(lib, ptx_name)
    with tempfile.TemporaryDirectory(prefix="clevrtex-cuda-") as work:
        ptx = os.path.join(work, "kernel.ptx")
        decompress(src, ptx)
        with open(ptx, "rb") as f:
            ptx_sha = hashlib.sha256(f.read()).hexdigest()
        cubin = os.path.join(work, f"kernel_sm_{sm}.cubin")
        t = time.monotonic()
        # The options the driver's JIT uses for Cycles' PTX: full optimisation, code for
        # exactly this GPU generation.
        r = subprocess.run([ptxas, f"--gpu-name=sm_{sm}", "-O3", ptx, "-o", cubin],
                           capture_output=True, text=True)
        took = time.monotonic() - t
        if r.returncode != 0 or not os.path.isfile(cubin):
            raise Refused(f"ptxas failed to compile `{ptx_name}` for sm_{sm}: {r.stderr.strip()[-500:]}",
                          "hint: a newer `nvidia-cuda-nvcc-cu12` (or CUDA toolkit) may be needed for this GPU")
        r = subprocess.run(["zstd", "-q", "-f", cubin, "-o", cubin + ".zst"], capture_output=True, text=True)
        if r.returncode != 0:
            raise Refused(f"cannot compress the kernel: {r.stderr.strip()}", "hint: install zstd (`apt-get install zstd`)")
        with open(cubin + ".zst", "rb") as f:
            data = f.read()
    write_atomic(os.path.join(lib, f"kernel_sm_{sm}.cubin.zst"), data)
    return {"sm": sm, "from": ptx_name, "ptx_sha256": ptx_sha, "ptxas": ptxas_version,
            "compile_s": round(took, 1), "bytes": len(data)}


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--cuda-arch", default="90", help="compute capabilities, e.g. 80,90")
    ap.add_argument("--bpy-python", default=".venv-bpy/bin/python")
    ap.add_argument("--cycles-lib", default=None, help="the Cycles add-on's lib folder (default: bpy's)")
    ap.add_argument("--ptxas", default=None)
    ap.add_argument("--cuda-venv", default=".venv-cuda", help=f"where {PACKAGE} is installed if needed")
    ap.add_argument("--jobs", type=int, default=os.cpu_count() or 1)
    ap.add_argument("--force", action="store_true", help="recompile kernels this script made before")
    ap.add_argument("--check", action="store_true", help="only check `--cuda-arch` (setup.sh, up front)")
    ap.add_argument("--install-ptxas", action="store_true", help="only install ptxas (into `--cuda-venv`)")
    a = ap.parse_args(argv)
    archs = parse_archs(a.cuda_arch)
    if a.check:
        return 0
    if a.install_ptxas:
        print(f"cuda kernels: ptxas: {find_ptxas(a)}")
        return 0
    lib = a.cycles_lib or cycles_lib_of(a.bpy_python)
    if not os.path.isdir(lib):
        raise Refused(f"`{lib}` is not a folder", "hint: pass the Cycles add-on's `lib` folder with `--cycles-lib`")
    cubins, ptxs, prepared = kernels_in(lib, "cubin"), kernels_in(lib, "ptx"), read_manifest(lib)
    todo = []
    for sm in archs:
        if sm in cubins and sm not in prepared:
            print(f"cuda kernels: sm_{sm}: shipped with this Blender ({cubins[sm]}), nothing to do")
            continue
        older = [p for p in ptxs if p <= sm]
        if not older:
            raise Refused(f"this Blender ships no PTX older than sm_{sm} to compile (PTX: "
                          f"{', '.join(f'compute_{p}' for p in sorted(ptxs)) or 'none'})",
                          "hint: use a bpy from PyPI (`./scripts/setup.sh --bpy 4.5`)")
        src = ptxs[max(older)]
        if sm in cubins and sm in prepared and prepared[sm].get("from") == src and not a.force:
            print(f"cuda kernels: sm_{sm}: prepared before from {src} ({cubins[sm]}), nothing to do")
            continue
        todo.append((sm, src))
    if not todo:
        return 0
    ptxas = find_ptxas(a)
    v = subprocess.run([ptxas, "--version"], capture_output=True, text=True).stdout.strip().splitlines()
    version = v[-1] if v else "unknown"
    print(f"cuda kernels: compiling {', '.join(f'sm_{s} from {p}' for s, p in todo)} with {ptxas} "
          f"({version}); a full Cycles kernel takes ~16 CPU-minutes each", flush=True)
    with concurrent.futures.ThreadPoolExecutor(max_workers=max(1, a.jobs)) as pool:
        done = list(pool.map(lambda t: prepare_one(lib, ptxas, t[0], t[1], version), todo))
    for d in done:
        prepared[d["sm"]] = d
        path = os.path.join(lib, "kernel_sm_%d.cubin.zst" % d["sm"])
        print(f"cuda kernels: sm_{d['sm']}: prepared {path} from {d['from']} in {d['compile_s']} s")
    doc = {"made_by": "clevrtex scripts/cuda_kernels.py", "kernels": [prepared[k] for k in sorted(prepared)]}
    write_atomic(os.path.join(lib, MANIFEST), (json.dumps(doc, indent=1) + "\n").encode())
    return 0


if __name__ == "__main__":
    try:
        sys.exit(main())
    except Refused as e:
        print(f"error: {e}\n{e.hint}", file=sys.stderr)
        sys.exit(e.code)
