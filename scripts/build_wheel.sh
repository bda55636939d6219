#!/usr/bin/env bash
# Builds the Python package `clevrtex` (crates/python) once, as one wheel for every CPython 3.8+
# on this OS and CPU (PyO3's stable ABI, abi3), into DIST (default: dist/). Install that file on
# the machines of a cluster with `pip install clevrtex-*.whl`: they need no Rust and no build.
#
#   ./scripts/build_wheel.sh [DIST]        PYTHON=python3.11 picks the Python that builds it
#
# Cargo's build folder is kept outside the source tree, in
# ${XDG_CACHE_HOME:-~/.cache}/clevrtex/python-target (CARGO_TARGET_DIR overrides it), so a
# rebuild reuses it and the clone stays small. Needs Rust >= 1.89 and pip (which fetches maturin).
set -euo pipefail
cd "$(dirname "$0")/.."
dist="${1:-dist}"
python="${PYTHON:-python3}"
export CARGO_TARGET_DIR="${CARGO_TARGET_DIR:-${XDG_CACHE_HOME:-$HOME/.cache}/clevrtex/python-target}"
mkdir -p "$dist"
"$python" -m pip wheel --quiet --disable-pip-version-check --no-deps --wheel-dir "$dist" ./crates/python
wheel=$(ls -t "$dist"/clevrtex-*.whl | head -n 1)
echo "built $wheel ($(du -h "$wheel" | cut -f1)); install it anywhere with: pip install $wheel"
