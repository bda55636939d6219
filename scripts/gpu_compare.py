#!/usr/bin/env python3
"""Compare a GPU run with CPU runs of the same seed (the comparison step of scripts/gpu_check.sh).

    gpu_compare.py --gpu GPU_OUT --cpu CPU_OUT --cpu-low CPU_LOW_OUT VARIANT [VARIANT ...]

GPU_OUT and CPU_OUT are `clevrtex generate --out` folders of the same variants, seed, size and
samples (e.g. 64), on the GPU and on the CPU; CPU_LOW_OUT is the CPU at fewer samples (e.g. 16),
same seed. For every image the CPU made (CPU_OUT may hold fewer images than GPU_OUT):

- masks (`<stem>_flat.png`) must be byte-identical: the layout, visibility check and mask
  encoding do not depend on the device;
- the RGB image must differ from the CPU's by no more than the CPU's own noise: the RMSE
  (0-255 RGB values) between GPU and CPU at the full samples must stay below the RMSE between the
  CPU at the full and at the low samples. Monte Carlo noise falls as 1/sqrt(samples), so the
  CPU's full-vs-low difference is about its low-sample noise; two unbiased renders at the full
  samples differ by less. A GPU that renders a material, light or colour differently exceeds it.

Prints one line per image and a summary; exit 0 when all pass, 1 when any fails, 2 on bad input.
Needs numpy and Pillow (the test venv has both).
"""

import argparse
import glob
import os
import sys

try:
    import numpy as np
    from PIL import Image
except ImportError as e:  # pragma: no cover - told to the user
    sys.exit(f"error: {e}\nhint: run with a Python that has numpy and Pillow (`.venv-test/bin/python`)")


def stems(out, variant):
    """Stems of the complete samples (metadata written last) of `variant` under `out`."""
    root = os.path.join(out, f"clevrtex_{variant}")
    found = {}
    for meta in glob.glob(os.path.join(root, "*", f"CLEVRTEX_{variant}_*.json")):
        stem = os.path.basename(meta)[: -len(".json")]
        found[stem] = os.path.dirname(meta)
    return found


def rgb(path):
    with Image.open(path) as im:
        return np.asarray(im.convert("RGB"), dtype=np.float64)


def rmse(a, b):
    if a.shape != b.shape:
        return float("inf")
    return float(np.sqrt(np.mean((a - b) ** 2)))


def compare(gpu, cpu, cpu_low, variants, out=sys.stdout):
    """Print the comparison; return the number of images that failed (or raise ValueError on
    bad input)."""
    failed = 0
    checked = 0
    for variant in variants:
        g, c, low = stems(gpu, variant), stems(cpu, variant), stems(cpu_low, variant)
        if not c:
            raise ValueError(f"no `{variant}` images in the CPU run `{cpu}`")
        for stem in sorted(c):
            if stem not in g or stem not in low:
                raise ValueError(f"`{stem}` is in the CPU run but not in the GPU run or the low-sample CPU run")
            checked += 1
            problems = []
            with open(os.path.join(g[stem], stem + "_flat.png"), "rb") as f:
                gm = f.read()
            with open(os.path.join(c[stem], stem + "_flat.png"), "rb") as f:
                cm = f.read()
            if gm != cm:
                problems.append("masks differ")
            gi, ci = rgb(os.path.join(g[stem], stem + ".png")), rgb(os.path.join(c[stem], stem + ".png"))
            li = rgb(os.path.join(low[stem], stem + ".png"))
            gpu_cpu, cpu_noise = rmse(gi, ci), rmse(ci, li)
            if not gpu_cpu <= cpu_noise:
                problems.append(f"RGB differs by more than the CPU's own noise ({gpu_cpu:.2f} > {cpu_noise:.2f})")
            print(f"{stem}: mask {'identical' if gm == cm else 'DIFFERENT'}, RGB RMSE GPU-CPU {gpu_cpu:.2f}, "
                  f"CPU noise (full vs low samples) {cpu_noise:.2f}: {'ok' if not problems else 'FAIL: ' + '; '.join(problems)}",
                  file=out)
            failed += bool(problems)
    print(f"compared {checked} image(s): {checked - failed} ok, {failed} failed", file=out)
    return failed


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--gpu", required=True)
    ap.add_argument("--cpu", required=True)
    ap.add_argument("--cpu-low", required=True)
    ap.add_argument("variants", nargs="+")
    a = ap.parse_args(argv)
    try:
        failed = compare(a.gpu, a.cpu, a.cpu_low, a.variants)
    except (ValueError, OSError) as e:
        print(f"error: {e}\nhint: pass the `--out` folders of the GPU and CPU runs of scripts/gpu_check.sh", file=sys.stderr)
        return 2
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
