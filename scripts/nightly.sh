#!/usr/bin/env bash
# Nightly-style checks too slow for every CI run (issue 6): the ignored extreme cases
# (e.g. a 1920x1440 render) and the quick error-vs-time benchmark. Needs Blender.
# Usage: scripts/nightly.sh [OUT]   (OUT defaults to target/nightly)
set -euo pipefail
cd "$(dirname "$0")/.."
out="${1:-target/nightly}"
export CLEVRTEX_REQUIRE_TOOLS=1
cargo test --test integration --locked -- --ignored
# PyPI's bpy 5.0 (in its own venv, so CI's 4.5 in .venv-bpy/ stays): the real-render suites
# that run on every Blender found, with 5.0 as the second one. The cross-version test is
# skipped: its tolerances are measured for 4.5 (see docs/scene-format.md).
if [ ! -x .venv-bpy50/bin/python ] || ! .venv-bpy50/bin/python -c 'import bpy' >/dev/null 2>&1; then
  python3 -m venv .venv-bpy50
  .venv-bpy50/bin/pip install --quiet --disable-pip-version-check 'bpy==5.0.*'
fi
CLEVRTEX_TEST_BPY="$PWD/.venv-bpy50/bin/python" CLEVRTEX_REQUIRE_BPY=1 \
  cargo test --test integration --locked -- generate:: passes:: shadow:: resume:: ledger:: blender_failures:: extreme:: --skip blenders::
cargo run --locked --quiet -- bench render --quick --out "$out/bench"
