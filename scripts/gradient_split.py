#!/usr/bin/env python3
"""Where does the interior gradient of the 128 crop come from? (issue 23, study)

For every region (each object id, and the background 0) of a rendered dataset with the rgb,
mask and albedo passes, on the evaluator's 128x128 centre crop (`segmentation_baselines.crop_box`:
side int(0.8 min(W, H)), bilinear; the mask nearest), with the interior and boundary pixels and
the luminance gradient of `clevrtex materials measure` (central differences of
0.299 R + 0.587 G + 0.114 B, interior = one id in the 7x7 neighbourhood):

- `rgb`: the mean interior gradient of the rendered image (what the gradient ratio uses),
- `alb`: the same on the albedo pass (base colour only: the colour contrast of the texture),
- `kept`: the rendered image's mean interior gradient at 128 over the same at the crop's
  native size, times the native-to-128 pixel ratio (1.5 at 320x240): 1 for structure
  much coarser than a pixel of the 128 crop, lower where the texture's energy sits at 1-2
  native pixels and the resize averages it away,
- `shade`: rgb / (alb x the region's mean rgb over mean albedo luminance): above 1, shading
  and bump add structure the base colour does not have; below 1, lighting flattens it.

Prints one row per material (medians over its regions), sorted by `rgb`; the backdrop's rows
are marked `bg`, and the images' median boundary gradient for scale.

    .venv-stats/bin/python scripts/gradient_split.py OUT
"""

import glob
import os
import re
import sys
import json
from collections import defaultdict

import numpy as np
from PIL import Image

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from segmentation_baselines import SIDE, crop_box  # noqa: E402


def lum(a):
    a = a.astype(np.float64)
    return 0.299 * a[..., 0] + 0.587 * a[..., 1] + 0.114 * a[..., 2]


def grad(y):
    gx = np.zeros_like(y)
    gy = np.zeros_like(y)
    gx[:, 1:-1] = (y[:, 2:] - y[:, :-2]) / 2
    gy[1:-1, :] = (y[2:, :] - y[:-2, :]) / 2
    return np.hypot(gx, gy)


def one_id(ids, r):
    """True where the (2r+1)^2 neighbourhood (inside the image) holds one id."""
    h, w = ids.shape
    ok = np.ones_like(ids, dtype=bool)
    for dy in range(-r, r + 1):
        for dx in range(-r, r + 1):
            sh = np.full_like(ids, -1)
            ys, yd = (slice(dy, h), slice(0, h - dy)) if dy >= 0 else (slice(0, h + dy), slice(-dy, h))
            xs, xd = (slice(dx, w), slice(0, w - dx)) if dx >= 0 else (slice(0, w + dx), slice(-dx, w))
            sh[yd, xd] = ids[ys, xs]
            ok &= (sh == ids) | (sh == -1)
    return ok


def crops(png, suffix):
    img = Image.open(png[:-4] + suffix).convert("RGB") if suffix else Image.open(png).convert("RGB")
    box = crop_box(*img.size)
    c = img.crop(box)
    return np.asarray(c.resize((SIDE, SIDE), Image.BILINEAR)), np.asarray(c), box


def main():
    root = sys.argv[1]
    pngs = sorted(p for p in glob.glob(os.path.join(root, "**", "CLEVRTEX_*.png"), recursive=True)
                  if re.match(r"^CLEVRTEX_[^_]+_\d{6,}\.png$", os.path.basename(p)))
    rows = defaultdict(list)
    bnd = []
    for png in pngs:
        meta = json.load(open(png[:-4] + ".json"))
        names = {0: meta["ground_material"]}
        for o in meta["objects"]:
            names[o["index"]] = o["material"]
        rgb, rgb_nat, box = crops(png, "")
        alb, _, _ = crops(png, "_albedo_0001.png")
        mask = Image.open(png[:-4] + "_flat.png").crop(box)
        ids = np.asarray(mask.resize((SIDE, SIDE), Image.NEAREST)).astype(np.int64)
        ids_nat = np.asarray(mask).astype(np.int64)
        g, ga = grad(lum(rgb)), grad(lum(alb))
        g_nat = grad(lum(rgb_nat))
        inner, inner_nat = one_id(ids, 3), one_id(ids_nat, 4)
        boundary = ~one_id(ids, 1)
        b = g[boundary].mean()
        bnd.append(b)
        px = rgb_nat.shape[0] / SIDE
        for i in np.unique(ids):
            m, mn = inner & (ids == i), inner_nat & (ids_nat == i)
            if m.sum() < 20 or mn.sum() < 40:
                continue
            la, lr = lum(alb)[m].mean(), lum(rgb)[m].mean()
            r, a = g[m].mean(), ga[m].mean()
            rows[(names[int(i)], "bg" if i == 0 else "obj")].append(
                (r, r / b, a, r / (g_nat[mn].mean() * px), r / max(a * lr / max(la, 1), 1e-6)))
    print("%-24s %-3s %4s %6s %6s %6s %6s %6s" % ("material", "", "n", "rgb", "ratio", "alb", "kept", "shade"))
    for (name, kind), v in sorted(rows.items(), key=lambda kv: np.median([x[0] for x in kv[1]])):
        med = np.median(np.array(v), axis=0)
        print("%-24s %-3s %4d %6.2f %6.2f %6.2f %6.2f %6.2f" % (name, kind, len(v), *med))
    print("boundary gradient, median over %d images: %.2f" % (len(bnd), np.median(bnd)))
    return 0


if __name__ == "__main__":
    sys.exit(main())
