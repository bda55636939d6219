#!/usr/bin/env python3
"""Flat-lit tile figures of a material at an object's and at the backdrop's scale (issue 23).

The third and fourth passes of issue 23 chose and checked materials with these figures
(docs/notes/materials.md, "Third pass" and "Fourth pass"). Each material is copied as a user
material at 2x and 4x density (32 and 16 px per material unit on a 128 px tile, as on an
object and on the backdrop of a 320x240 image), rendered flat-lit by `clevrtex materials
stats`, and measured on the two `random` instances (r0, r1; the figures are their mean):

- `spread`: CIELAB spread of the 2x tile, sRGB to Lab (D65), sqrt(var L + var a + var b),
- `grad2`, `grad4`: mean luminance gradient (0.299 R + 0.587 G + 0.114 B, 0..255, central
  differences) after a Pillow bilinear resize to 2/3 (the 128 crop's 192 -> 128 at 320x240),
  at 2x and 4x density.

    .venv-stats/bin/python scripts/tile_figures.py prep DIR b materials/main oak_flooring rope
    clevrtex materials stats --names b2_oak_flooring,b4_oak_flooring,b2_rope,b4_rope \
        --materials DIR --size 128 --samples 8 --out-dir TILES
    .venv-stats/bin/python scripts/tile_figures.py fig TILES b@_oak_flooring b@_rope

`prep DIR TAG SRC NAME...` writes DIR/TAG2_NAME.json and DIR/TAG4_NAME.json from
SRC/NAME.json (a second TAG, from another checkout's files, gives before and after in one
run); in `fig`, `@` in a name stands for the density (2 or 4).
"""

import json
import os
import sys

import numpy as np
from PIL import Image


def prep(out, tag, src, names):
    os.makedirs(out, exist_ok=True)
    for name in names:
        with open(os.path.join(src, name + ".json")) as f:
            material = json.load(f)
        for k in (2, 4):
            copy = dict(material, scale=material.get("scale", 1.0) * k)
            with open(os.path.join(out, f"{tag}{k}_{name}.json"), "w") as f:
                json.dump(copy, f)


def lab(rgb):
    c = rgb / 255.0
    c = np.where(c <= 0.04045, c / 12.92, ((c + 0.055) / 1.055) ** 2.4)
    m = np.array([[0.4124564, 0.3575761, 0.1804375],
                  [0.2126729, 0.7151522, 0.0721750],
                  [0.0193339, 0.1191920, 0.9503041]])
    xyz = c @ m.T / np.array([0.95047, 1.0, 1.08883])
    f = np.where(xyz > (6 / 29) ** 3, np.cbrt(xyz), xyz / (3 * (6 / 29) ** 2) + 4 / 29)
    return np.stack([116 * f[..., 1] - 16, 500 * (f[..., 0] - f[..., 1]),
                     200 * (f[..., 1] - f[..., 2])], -1)


def spread(img):
    values = lab(np.asarray(img.convert("RGB"), dtype=np.float64)).reshape(-1, 3)
    return float(np.sqrt(values.var(0).sum()))


def gradient(img):
    img = img.convert("RGB")
    img = img.resize((img.width * 2 // 3, img.height * 2 // 3), Image.BILINEAR)
    a = np.asarray(img, dtype=np.float64)
    lum = 0.299 * a[..., 0] + 0.587 * a[..., 1] + 0.114 * a[..., 2]
    gx = (lum[1:-1, 2:] - lum[1:-1, :-2]) / 2
    gy = (lum[2:, 1:-1] - lum[:-2, 1:-1]) / 2
    return float(np.hypot(gx, gy).mean())


def figures(tiles, names):
    for name in names:
        v = {}
        for k in (2, 4):
            stem = name.replace("@", str(k))
            imgs = [Image.open(os.path.join(tiles, r, stem + ".png")) for r in ("r0", "r1")]
            v[k] = (np.mean([spread(i) for i in imgs]), np.mean([gradient(i) for i in imgs]))
        print(f"{name:32s} spread {v[2][0]:5.1f}  grad2 {v[2][1]:5.1f}  grad4 {v[4][1]:5.1f}")


def main(argv):
    if len(argv) >= 5 and argv[1] == "prep":
        prep(argv[2], argv[3], argv[4], argv[5:])
    elif len(argv) >= 3 and argv[1] == "fig":
        figures(argv[2], argv[3:])
    else:
        sys.exit(__doc__)


if __name__ == "__main__":
    main(sys.argv)
