#!/usr/bin/env bash
# The GPU check of issue 35, prepared to run as one command on a machine with an NVIDIA GPU, in
# about 8 minutes: `clevrtex doctor`; 16 images each of clevr, full and camo at 320x240, 64
# samples on the GPU and 4 each on this machine's CPU (and the same 4 at 16 samples, the CPU's
# own noise) with the same seed; masks byte-identical and RGB within the CPU's noise
# (scripts/gpu_compare.py); images/hour per GPU and per CPU core; 32 `full` images with 4 and
# with 8 workers per GPU (issue 40: 8 is allowed, not yet measured); the first render's start-up.
#
#   ./scripts/gpu_check.sh [WORK]     (WORK: a scratch folder, default a fresh one in $TMPDIR)
#
# Environment: CLEVRTEX (default target/release/clevrtex, built if missing), BLENDER (default
# .venv-bpy/bin/python: PyPI's bpy, whose kernels `./scripts/setup.sh --bpy 4.5 --cuda-arch 80,90`
# prepares first), DEVICE (cuda), PYTHON (numpy + Pillow; default .venv-test/bin/python, else
# python3), NVIDIA_SMI (nvidia-smi). Exit 0 when every check passes, 1 when one fails or there is
# no GPU.
set -euo pipefail
cd "$(dirname "$0")/.."
: "${NVIDIA_SMI:=nvidia-smi}"
: "${CLEVRTEX:=target/release/clevrtex}"
: "${BLENDER:=.venv-bpy/bin/python}"
: "${DEVICE:=cuda}"
if [ -z "${PYTHON:-}" ]; then
  if [ -x .venv-test/bin/python ]; then PYTHON=.venv-test/bin/python; else PYTHON=python3; fi
fi
if ! gpus="$("$NVIDIA_SMI" --query-gpu=name,compute_cap --format=csv,noheader 2>/dev/null)" || [ -z "$gpus" ]; then
  echo "error: no NVIDIA GPU here (\`$NVIDIA_SMI\` lists none), so there is nothing to check" >&2
  echo "hint: run this on a machine with an NVIDIA GPU and its driver; on a CPU machine, plan runs with \`clevrtex generate ... --estimate\`" >&2
  exit 1
fi
ngpu=$(printf '%s\n' "$gpus" | wc -l)
cores=$(nproc)
if [ ! -x "$CLEVRTEX" ]; then cargo build --release --locked --bin clevrtex; fi
work="${1:-$(mktemp -d "${TMPDIR:-/tmp}/clevrtex-gpu-check-XXXXXX")}"
mkdir -p "$work"
echo "gpu check: $ngpu GPU(s): $(printf '%s' "$gpus" | paste -sd ';'); $cores CPU core(s); work folder $work"

"$CLEVRTEX" doctor --blender "$BLENDER"

common=(--seed 35 --width 320 --height 240 --blender "$BLENDER")
now() { date +%s.%N; }
secs() { awk -v a="$1" -v b="$2" 'BEGIN { print b - a }'; }

# The first render's start-up: a worker's start, its kernel load (or compile) and one tiny image.
t0=$(now)
"$CLEVRTEX" generate --variant clevr -n 1 --width 64 --height 48 --samples 1 --device "$DEVICE" \
  --blender "$BLENDER" --out "$work/warm" > "$work/warm.log" 2>&1
startup=$(secs "$t0" "$(now)")

t0=$(now)
for v in clevr full camo; do
  "$CLEVRTEX" generate --variant "$v" -n 16 --samples 64 --device "$DEVICE" "${common[@]}" \
    --out "$work/gpu" > "$work/gpu-$v.log" 2>&1
done
gpu_s=$(secs "$t0" "$(now)")

t0=$(now)
for v in clevr full camo; do
  "$CLEVRTEX" generate --variant "$v" -n 4 --samples 64 --device cpu "${common[@]}" \
    --out "$work/cpu" > "$work/cpu-$v.log" 2>&1
done
cpu_s=$(secs "$t0" "$(now)")
for v in clevr full camo; do
  "$CLEVRTEX" generate --variant "$v" -n 4 --samples 16 --device cpu "${common[@]}" \
    --out "$work/cpu16" > "$work/cpu16-$v.log" 2>&1
done

# Workers per GPU (issue 40): `full` with 4 (the default's most) and 8 (allowed, not yet
# measured) workers per GPU, each with cores / workers Cycles threads.
sweep=()
for w in 4 8; do
  ws=$((w * ngpu))
  t=$((cores / ws)); [ "$t" -ge 1 ] || t=1
  t0=$(now)
  "$CLEVRTEX" generate --variant full -n 32 --samples 64 --device "$DEVICE" --workers "$ws" \
    --threads "$t" "${common[@]}" --out "$work/sweep-$w" > "$work/sweep-$w.log" 2>&1
  sweep+=("$(awk -v w="$w" -v t="$t" -v s="$(secs "$t0" "$(now)")" -v n="$ngpu" \
    'BEGIN { printf "| full, %d workers per GPU x %d threads | 32 | %.1f | %.0f per GPU |", w, t, s, 32 / s * 3600 / n }')")
done

status=0
"$PYTHON" scripts/gpu_compare.py --gpu "$work/gpu" --cpu "$work/cpu" --cpu-low "$work/cpu16" \
  clevr full camo || status=1
if grep -l "compiles PTX\|has no ready-made Cycles kernel" "$work"/gpu-*.log "$work/warm.log" >/dev/null 2>&1; then
  echo "FAIL: a worker compiled its CUDA kernel at run time (see $work/*.log)"
  status=1
fi

gpu_rate=$(awk -v s="$gpu_s" -v n="$ngpu" 'BEGIN { print 48 / s * 3600 / n }')
cpu_rate=$(awk -v s="$cpu_s" -v n="$cores" 'BEGIN { print 12 / s * 3600 / n }')
echo
echo "| what | images | wall s | images/hour |"
echo "|---|---|---|---|"
printf '| GPU (%s, %s), 320x240, 64 spp, clevr+full+camo | 48 | %.1f | %.0f per GPU |\n' "$DEVICE" "$(printf '%s' "$gpus" | head -n 1)" "$gpu_s" "$gpu_rate"
printf '| CPU (%s cores), same | 12 | %.1f | %.1f per core |\n' "$cores" "$cpu_s" "$cpu_rate"
printf '%s\n' "${sweep[@]}"
printf '| first render start-up (worker start, kernel load, one 64x48 image) | 1 | %.1f | |\n' "$startup"
echo "command: ./scripts/gpu_check.sh (logs in $work)"
exit $status
