#!/usr/bin/env bash
# Images/hour by workers x Cycles threads on this machine (issue 35): the measurement behind
# `generate`'s default worker count. Each cell is `clevrtex generate -n N` of one variant into a
# fresh folder; the images/hour is the run's own summary line (Blender starts included). The load
# average is printed before and after: on a shared machine, say it with the table.
#
#   scripts/workers_sweep.sh [WORKERS [THREADS [N [ARGS...]]]]
#   e.g. scripts/workers_sweep.sh "1 2" "1 2" 6 --variant full --width 96 --height 72 --samples 16
set -euo pipefail
cd "$(dirname "$0")/.."
workers="${1:-1 2}"
threads="${2:-1 2}"
n="${3:-6}"
shift $(( $# < 3 ? $# : 3 ))
args=("$@")
[ ${#args[@]} -gt 0 ] || args=(--variant full --width 96 --height 72 --samples 16)
: "${CLEVRTEX:=target/debug/clevrtex}"
echo "load average before: $(cut -d' ' -f1-3 /proc/loadavg); $(nproc) core(s)"
echo "| workers | threads | images | wall s | images/hour |"
echo "|---|---|---|---|---|"
for w in $workers; do
  for t in $threads; do
    out="$(mktemp -d "${TMPDIR:-/tmp}/clevrtex-sweep-XXXXXX")"
    line="$("$CLEVRTEX" generate -n "$n" --seed 0 --workers "$w" --threads "$t" --device cpu \
      "${args[@]}" --out "$out" 2>/dev/null | grep -E '^rendered|images/hour')"
    rm -rf "$out"
    wall="$(printf '%s\n' "$line" | sed -n 's/.* in \([0-9.]*\) s with.*/\1/p')"
    rate="$(printf '%s\n' "$line" | sed -n 's/.*, \([0-9]*\) images\/hour/\1/p')"
    echo "| $w | $t | $n | $wall | $rate |"
  done
done
echo "load average after: $(cut -d' ' -f1-3 /proc/loadavg)"
echo "command: scripts/workers_sweep.sh \"$workers\" \"$threads\" $n ${args[*]}"
