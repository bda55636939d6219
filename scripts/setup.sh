#!/usr/bin/env bash
# Installs what clevrtex needs on Debian 12 besides Rust: Debian's headless-capable Blender
# (3.4.1) and the rustfmt/clippy components the test command uses. Needs root (or sudo).
#
#   ./scripts/setup.sh               Blender (apt) and the Rust components
#   ./scripts/setup.sh --test-venv   also `.venv-test/`: a Python venv with the libraries the
#                                    tests read our files with (webdataset, Hugging Face datasets, PyYAML) and the
#                                    eval reference harness's (numpy, scipy, scikit-learn, Pillow),
#                                    and the Python package `clevrtex` (crates/python) with pytest
#   ./scripts/setup.sh --bpy 4.5     also `.venv-bpy/`: a Python venv with PyPI's `bpy` 4.5 LTS
#                                    (or `--bpy 5.0`), a second Blender: pass
#                                    `--blender .venv-bpy/bin/python` to clevrtex
#   ./scripts/setup.sh --bpy 4.5 --cuda-arch 80,90
#                                    also compile, once and without a GPU, the Cycles CUDA kernels
#                                    bpy lacks for these compute capabilities (8.0 A100, 9.0 H100/
#                                    H200) with `ptxas` from PyPI's nvidia-cuda-nvcc-cu12 (in
#                                    `.venv-cuda/`), into bpy's Cycles add-on where Cycles loads
#                                    ready-made kernels (scripts/cuda_kernels.py; ~16 CPU-minutes
#                                    per capability, in parallel), so no worker compiles at run time
#   ./scripts/setup.sh --ptxas       only `.venv-cuda/` with ptxas (the kernel tests' compiler)
#   ./scripts/setup.sh --browser     also Debian's `chromium`, for the report's browser test
#   ./scripts/setup.sh --torch       also PyTorch (PyPI's wheel) in `.venv-test/` (implies
#                                    --test-venv), for the training example
#                                    (examples/train_toy.py) and the DataLoader tests
#   ./scripts/setup.sh --slurm       also Debian's SLURM (munge, slurmctld, slurmd, slurm-client)
#                                    for tests/slurm.rs, which starts its own one-host cluster
#   ./scripts/setup.sh --all         everything the test suite uses, as `.ci/run` installs it:
#                                    --test-venv --torch --browser --bpy 4.5 --ptxas --slurm
set -euo pipefail
cd "$(dirname "$0")/.."
SUDO=""
if [ "$(id -u)" -ne 0 ]; then SUDO="sudo"; fi
test_venv=0
browser=0
torch=0
bpy=""
cuda_arch=""
ptxas=0
slurm=0
while [ $# -gt 0 ]; do
  case "$1" in
    --test-venv) test_venv=1 ;;
    --browser) browser=1 ;;
    --torch) torch=1; test_venv=1 ;;
    --bpy)
      bpy="${2:-}"
      shift
      case "$bpy" in
        4.5|5.0) ;;
        *) echo "setup.sh: \`--bpy ${bpy}\` is not a supported bpy version (known: 4.5, 5.0)" >&2; exit 2 ;;
      esac
      ;;
    --cuda-arch)
      cuda_arch="${2:-}"
      shift
      # Refused up front (exit 2), before anything is installed.
      python3 scripts/cuda_kernels.py --check --cuda-arch "$cuda_arch"
      ;;
    --ptxas) ptxas=1 ;;
    --slurm) slurm=1 ;;
    --all) test_venv=1; torch=1; browser=1; ptxas=1; slurm=1; bpy="${bpy:-4.5}" ;;
    *) echo "setup.sh: unknown option \`$1\` (known: --all, --test-venv, --torch, --bpy 4.5|5.0, --cuda-arch LIST, --ptxas, --browser, --slurm)" >&2; exit 2 ;;
  esac
  shift
done
# Refused up front (exit 2), before the apt step: `--cuda-arch` prepares the kernels of
# PyPI's bpy, which must be there or come with `--bpy`.
if [ -n "$cuda_arch" ] && [ -z "$bpy" ] && [ ! -x .venv-bpy/bin/python ]; then
  echo "setup.sh: \`--cuda-arch\` prepares the kernels of PyPI's bpy, and there is none in .venv-bpy" >&2
  echo "hint: add \`--bpy 4.5\`" >&2
  exit 2
fi

# Every Debian package in one apt run.
need=()
command -v blender >/dev/null 2>&1 || need+=(blender)
if { [ -n "$cuda_arch" ] || [ "$ptxas" = 1 ]; }; then
  command -v zstd >/dev/null 2>&1 || need+=(zstd)
  python3 -c 'import ensurepip, venv' >/dev/null 2>&1 || need+=(python3-venv)
fi
if { [ "$test_venv" = 1 ] || [ -n "$bpy" ]; } && ! python3 -c 'import ensurepip, venv' >/dev/null 2>&1; then
  need+=(python3-venv)
fi
if [ -n "$bpy" ]; then
  # PyPI's bpy wheels need a few X/GL libraries even headless.
  for p in libtbb12 libvulkan1 libx11-6 libxrender1 libxxf86vm1 libxfixes3 libxi6 libxkbcommon0 \
           libsm6 libgl1 libegl1; do
    dpkg -s "$p" >/dev/null 2>&1 || need+=("$p")
  done
fi
if [ "$slurm" = 1 ]; then
  for p in munge slurmctld slurmd slurm-client; do
    dpkg -s "$p" >/dev/null 2>&1 || need+=("$p")
  done
fi
# Chromium alone (no recommends: 122 MB of packages instead of a desktop's worth).
bare=()
if [ "$browser" = 1 ] && ! command -v chromium >/dev/null 2>&1; then
  bare+=(chromium)
fi
if [ ${#need[@]} -gt 0 ] || [ ${#bare[@]} -gt 0 ]; then
  $SUDO apt-get update
fi
if [ ${#need[@]} -gt 0 ]; then
  DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y "${need[@]}"
fi
if [ ${#bare[@]} -gt 0 ]; then
  DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y --no-install-recommends "${bare[@]}"
fi
if command -v rustup >/dev/null 2>&1; then
  rustup component add rustfmt clippy >/dev/null 2>&1 || true
fi
if [ "$test_venv" = 1 ]; then
  if ! .venv-test/bin/python -c 'import webdataset, yaml' >/dev/null 2>&1; then
    python3 -m venv .venv-test
    .venv-test/bin/pip install --quiet --disable-pip-version-check 'webdataset>=0.2,<2' 'pyyaml>=6'
  fi
  # Hugging Face `datasets`: tests/export.rs reads exported shards with its `webdataset` builder.
  if ! .venv-test/bin/python -c 'import datasets' >/dev/null 2>&1; then
    .venv-test/bin/pip install --quiet --disable-pip-version-check 'datasets>=2.16,<5'
  fi
  # pycocotools: tests/export.rs reads `export --format coco` files with it (and docs/output-format.md).
  if ! .venv-test/bin/python -c 'import pycocotools' >/dev/null 2>&1; then
    .venv-test/bin/pip install --quiet --disable-pip-version-check 'pycocotools>=2.0.7,<3'
  fi
  # tests/eval_reference/harness.py (the public evaluators in numpy; see docs/eval.md).
  if ! .venv-test/bin/python -c 'import numpy, scipy, sklearn, PIL' >/dev/null 2>&1; then
    .venv-test/bin/pip install --quiet --disable-pip-version-check numpy scipy scikit-learn pillow
  fi
  # The Python package (crates/python, PyO3 + maturin) as the one wheel scripts/build_wheel.sh
  # makes into dist/ (rebuilt each time so it follows the sources; cargo's build folder stays
  # outside the source tree and is reused), installed with pip like on any other machine;
  # tests/python_package.rs also installs that wheel into a fresh venv. pytest for its tests.
  .venv-test/bin/pip install --quiet --disable-pip-version-check pytest
  wheel="$(PYTHON=.venv-test/bin/python ./scripts/build_wheel.sh dist | sed -n 's/^built \([^ ]*\) .*/\1/p')"
  .venv-test/bin/pip install --quiet --disable-pip-version-check --force-reinstall --no-deps "$wheel"
  if [ "$torch" = 1 ] && ! .venv-test/bin/python -c 'import torch' >/dev/null 2>&1; then
    # PyPI's wheel (no CPU-only index is reachable from CI); pip keeps its download cache, so
    # a rerun does not fetch it again.
    .venv-test/bin/pip install --quiet --disable-pip-version-check torch
  fi
  echo "test venv: $(.venv-test/bin/python -c 'import webdataset, sys; print(sys.version.split()[0], "webdataset", getattr(webdataset, "__version__", "?"))')$(.venv-test/bin/python -c 'import torch; print(" torch", torch.__version__)' 2>/dev/null || true)"
fi
if [ -n "$bpy" ]; then
  # PyPI's bpy wheels need the Python minor version Blender was built with (3.11 for 4.5 and
  # 5.0, Debian 12's python3).
  want="${bpy}."
  have="$(.venv-bpy/bin/python -c 'import bpy; print(bpy.app.version_string)' 2>/dev/null || true)"
  if [ "${have#"$want"}" = "$have" ]; then
    rm -rf .venv-bpy
    python3 -m venv .venv-bpy
    .venv-bpy/bin/pip install --quiet --disable-pip-version-check "bpy==${bpy}.*"
  fi
  echo "bpy venv: .venv-bpy/bin/python: Blender $(.venv-bpy/bin/python -c 'import bpy; print(bpy.app.version_string)' 2>/dev/null)"
fi
if [ "$ptxas" = 1 ]; then
  python3 scripts/cuda_kernels.py --install-ptxas --cuda-venv .venv-cuda
fi
if [ -n "$cuda_arch" ]; then
  python3 scripts/cuda_kernels.py --cuda-arch "$cuda_arch" --bpy-python .venv-bpy/bin/python --cuda-venv .venv-cuda
fi
echo "blender: $(blender --version 2>/dev/null | head -n 1)"
if [ "$browser" = 1 ]; then
  echo "browser: $(chromium --version 2>/dev/null | head -n 1)"
fi
