#!/usr/bin/env bash
# The outputs of the commands that read a dataset, for a before/after comparison of a refactor
# (issue 36: "outputs byte-identical"): run it with the old and the new binary on the same
# dataset and predictions, then `diff -r BEFORE AFTER`.
#
#   ./scripts/same_outputs.sh CLEVRTEX DATA PREDS OTHER OUT
#
# CLEVRTEX: the binary; DATA: a dataset (`generate --out`); PREDS: predictions for `eval`;
# OTHER: a second dataset for `report --compare`; OUT: a fresh folder for the outputs. Each
# command's exit status, stdout and stderr are kept (timings and the output folder's name are
# replaced, since they differ by run).
set -uo pipefail
if [ $# -ne 5 ]; then sed -n 2,12p "$0" >&2; exit 2; fi
bin="$1" data="$2" preds="$3" other="$4" out="$5"
mkdir -p "$out"
run() { # NAME ARGS...: runs the binary, keeps rc, stdout and a stable stderr
  local name="$1"; shift
  "$bin" "$@" > "$out/$name.stdout.raw" 2> "$out/$name.stderr.raw"
  echo "$?" > "$out/$name.rc"
  for s in stdout stderr; do # timings and the output folder's name differ by run
    sed -E -e "s#$out/#OUT/#g" -e 's/[0-9]+(\.[0-9]+)? ?(ms|s|MB\/s|img\/s|samples\/s)\b/TIME/g' \
      "$out/$name.$s.raw" > "$out/$name.$s"
    rm -f "$out/$name.$s.raw"
  done
}
run verify verify "$data" --json "$out/verify.json" --jobs 2
run export export "$data" "$out/export"
run report report "$data" --out "$out/report.html"
run report-compare report "$data" --compare "$other" --out "$out/report-compare.html"
run preview preview "$data" --out "$out/preview.png" --n 8
run eval eval "$preds" "$data" --split all --native-size --json "$out/eval.json" --csv "$out/eval.csv"
run eval-ocl eval "$preds" "$data" --split all --native-size --protocol ocl --metrics all --json "$out/eval-ocl.json"
run eval-test eval "$preds" "$data" --native-size --json "$out/eval-test.json"
for f in "$out"/*.rc; do printf '%s=%s ' "$(basename "$f" .rc)" "$(cat "$f")"; done
echo "(exit statuses) in $out"
