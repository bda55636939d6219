#!/usr/bin/env bash
# The project's test command (README): format check, clippy with warnings denied, all tests,
# then a smoke render of 4 images checked end to end.
#
# A test whose external tool is missing (Blender, bpy, the test Python, Chromium, SLURM) skips
# and is listed under "skipped:" at the end, whatever else happened; `CLEVRTEX_REQUIRE_TOOLS=1`
# (and `CLEVRTEX_REQUIRE_BPY=1` for bpy) turns those skips into failures, as `.ci/run` does.
set -euo pipefail
cd "$(dirname "$0")/.."
CLEVRTEX_SKIP_LOG="$(mktemp "${TMPDIR:-/tmp}/clevrtex-skips.XXXXXX")"
export CLEVRTEX_SKIP_LOG
summary() {
  status=$?
  if [ -s "$CLEVRTEX_SKIP_LOG" ]; then
    echo "skipped: $(wc -l <"$CLEVRTEX_SKIP_LOG") test(s) whose tools are missing:"
    sort "$CLEVRTEX_SKIP_LOG" | sed 's/^/  skipped: /'
  else
    echo "skipped: none"
  fi
  rm -f "$CLEVRTEX_SKIP_LOG"
  exit "$status"
}
trap summary EXIT
cargo fmt --all -- --check
cargo clippy --workspace --all-targets --locked -- -D warnings
# One test thread more than the CPUs: the integration tests spend much of their time waiting
# (Blender starting, hung fake workers timing out, SLURM), and with one thread per CPU the
# cores sat idle a third of the time (docs/notes/performance.md, "The test command's time").
threads="${CLEVRTEX_TEST_THREADS:-$(($(nproc) + 1))}"
cargo test --workspace --locked -- --test-threads="$threads"
if [ -x scripts/smoke.sh ]; then ./scripts/smoke.sh; fi
