#!/usr/bin/env python3
"""How hard is a dataset for segmenters that use no learning? (issue 23, deliverable 5)

ARI-FG (the adjusted Rand index over the ground truth's foreground pixels, as the
benchmark's FG-ARI) of three unsupervised segmenters on the evaluator's 128x128 centre crop
(side int(0.8 min(W, H)), bilinear; the mask nearest):

- k-means on RGB,
- k-means on CIELAB plus pixel position (x, y scaled so that the image's side spans 100
  Lab units, as L does),
- Felzenszwalb's graph segmentation (scale 100, sigma 0.5, min_size 20),

with k (for k-means) the number of ids in the crop's ground truth: an oracle count, which
favours k-means. Higher is easier; a dataset where colour gives the objects away scores high.

    python3 -m venv .venv-stats
    .venv-stats/bin/pip install numpy scipy scikit-learn scikit-image pillow
    .venv-stats/bin/python scripts/segmentation_baselines.py OUT [OUT2 ...] [--limit N]

OUT is the --out of `clevrtex generate` (every `clevrtex_<variant>` under it) or one variant
folder. Prints one row per variant: images and, per method, the mean ARI-FG over the images
and its standard error (sample standard deviation / sqrt(images)). With two OUTs, also the
paired difference (second minus first) per variant over the image stems both hold, with the
standard error of the per-image differences: for before/after renders of the same seeds,
whose layouts are the same, this is far tighter than the two means' errors.
"""

import argparse
import glob
import os
import re
import sys

import numpy as np
from PIL import Image
from skimage.color import rgb2lab
from skimage.segmentation import felzenszwalb
from sklearn.cluster import KMeans
from sklearn.metrics import adjusted_rand_score

SIDE = 128


def crop_box(w, h):
    c = int(0.8 * min(w, h))
    x0, y0 = (w - c) // 2, (h - c) // 2
    return (x0, y0, x0 + c, y0 + c)


def load(png):
    stem = png[: -len(".png")]
    img = Image.open(png).convert("RGB")
    mask = Image.open(stem + "_flat.png")
    box = crop_box(*img.size)
    rgb = np.asarray(img.crop(box).resize((SIDE, SIDE), Image.BILINEAR))
    ids = np.asarray(mask.crop(box).resize((SIDE, SIDE), Image.NEAREST)).astype(np.int64)
    return rgb, ids


def ari_fg(ids, pred):
    fg = ids.ravel() != 0
    if len(np.unique(ids.ravel()[fg])) < 1 or fg.sum() == 0:
        return None
    return adjusted_rand_score(ids.ravel()[fg], pred.ravel()[fg])


def mean_se(xs):
    """`mean+-se` of the per-image scores: se the sample standard deviation over sqrt(n)."""
    if not xs:
        return "nan"
    se = np.std(xs, ddof=1) / np.sqrt(len(xs)) if len(xs) > 1 else float("nan")
    return "%.3f+-%.3f" % (np.mean(xs), se)


def segment(rgb, k, seed=0):
    out = {}
    x = rgb.reshape(-1, 3).astype(np.float64)
    out["kmeans_rgb"] = KMeans(k, n_init=4, random_state=seed).fit_predict(x)
    lab = rgb2lab(rgb).reshape(-1, 3)
    yy, xx = np.mgrid[0:SIDE, 0:SIDE]
    xy = np.stack([xx.ravel(), yy.ravel()], 1) * (100.0 / SIDE)
    out["kmeans_lab_xy"] = KMeans(k, n_init=4, random_state=seed).fit_predict(
        np.concatenate([lab, xy], 1))
    out["felzenszwalb"] = felzenszwalb(rgb, scale=100, sigma=0.5, min_size=20).ravel()
    return out


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("datasets", nargs="+")
    ap.add_argument("--limit", type=int, default=0, help="at most N images per variant")
    a = ap.parse_args()
    methods = ("kmeans_rgb", "kmeans_lab_xy", "felzenszwalb")
    per_image = {}  # (OUT, variant) -> image file name -> method -> ARI-FG
    print("%-28s %-8s %6s %15s %15s %15s" % ("dataset", "variant", "images", *methods))
    for root in a.datasets:
        vdirs = [root] if os.path.basename(root.rstrip("/")).startswith("clevrtex_") else \
            sorted(glob.glob(os.path.join(root, "clevrtex_*")))
        for vdir in vdirs:
            pngs = sorted(p for p in glob.glob(os.path.join(vdir, "*", "CLEVRTEX_*.png"))
                          if re.match(r"^CLEVRTEX_[^_]+_\d{6,}\.png$", os.path.basename(p)))
            if a.limit:
                pngs = pngs[: a.limit]
            scores = {m: [] for m in methods}
            variant = os.path.basename(vdir.rstrip("/"))[len("clevrtex_"):]
            for png in pngs:
                rgb, ids = load(png)
                k = max(2, len(np.unique(ids)))
                for m, pred in segment(rgb, k).items():
                    s = ari_fg(ids, pred)
                    if s is not None:
                        scores[m].append(s)
                        per_image.setdefault((root, variant), {}).setdefault(
                            os.path.basename(png), {})[m] = s
            print("%-28s %-8s %6d %15s %15s %15s" % (
                root[-28:], variant, len(pngs), *[mean_se(scores[m]) for m in methods]))
    if len(a.datasets) == 2:
        first, second = a.datasets
        for variant in sorted(set(v for (_, v) in per_image)):
            x, y = per_image.get((first, variant), {}), per_image.get((second, variant), {})
            both = sorted(set(x) & set(y))
            diffs = [mean_se([y[s][m] - x[s][m] for s in both if m in x[s] and m in y[s]])
                     for m in methods]
            print("%-28s %-8s %6d %15s %15s %15s" % (
                "paired difference", variant, len(both), *diffs))
    return 0


if __name__ == "__main__":
    sys.exit(main())
