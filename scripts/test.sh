#!/usr/bin/env bash
# The project's test command (README): format check, clippy with warnings denied, all tests,
# then a smoke render of 4 images checked end to end.
set -euo pipefail
cd "$(dirname "$0")/.."
cargo fmt --all -- --check
cargo clippy --workspace --all-targets --locked -- -D warnings
cargo test --workspace --locked
if [ -x scripts/smoke.sh ]; then ./scripts/smoke.sh; fi
