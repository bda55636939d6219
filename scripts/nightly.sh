#!/usr/bin/env bash
# Nightly-style checks too slow for every CI run (issue 6): the ignored extreme cases
# (e.g. a 1920x1440 render) and the quick error-vs-time benchmark. Needs Blender.
# Usage: scripts/nightly.sh [OUT]   (OUT defaults to target/nightly)
set -euo pipefail
cd "$(dirname "$0")/.."
out="${1:-target/nightly}"
export CLEVRTEX_REQUIRE_BLENDER=1
cargo test --test integration --locked -- --ignored
cargo run --locked --quiet -- bench render --quick --out "$out/bench"
