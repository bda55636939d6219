"""Split renders' error against references by light-path pass and by object (issue 24; dev).

    .venv-bpy/bin/python blender_scripts/dev/parity_compare.py OUT REF_TAG TAG [TAG ...]
        [--ref-dir OUT2] [--objects] [--pair]

Reads OUT/<scene>/<TAG>.exr written by `parity_measure.py` (for every scene folder of OUT that
has REF_TAG.exr; `--ref-dir`: the references are read from another OUT, e.g. another
version's, to compare means across versions). Per scene and tag it prints:

- the relative error of the Combined RGB (RMSE over every pixel and channel / the reference's
  mean, as `bench render`'s `rel_error`), its squared error over the reference's, the share
  of the squared error in the worst 0.1% of pixels, and the mean linear luminance;
- per light-path component (`DiffDir*DiffCol`, `DiffInd*DiffCol`, `GlossDir*GlossCol`, ...,
  `Emit`, `Env`): its share of the Combined squared error (the components' own errors; they
  add up to the total up to cross terms), its worst-0.1%-pixel share, and its mean luminance
  against the reference's;
- the means of the albedo AOV (`BaseCol`) and of the colour passes against the reference's;
- with `--objects`: the Combined squared error per object index (0: backdrop), with the
  objects' share of the pixels.
Also prints the time of each render (OUT/<scene>/<TAG>.json).

`--pair`: REF_TAG is not a converged reference but an independent render at the same samples
(another Cycles seed): the squared differences are halved, so they estimate each render's
variance, the noise part of its error against the truth (the bias part is left out; the
means show it). Cheap: no high-sample reference to render.
"""

import json
import os
import sys

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import exr_dump  # noqa: E402

LUM = np.array([0.2126, 0.7152, 0.0722])
COMPONENTS = [
    ("DiffDir", "DiffCol"), ("DiffInd", "DiffCol"),
    ("GlossDir", "GlossCol"), ("GlossInd", "GlossCol"),
    ("TransDir", "TransCol"), ("TransInd", "TransCol"),
    ("Emit", None), ("Env", None),
]


def load(path):
    w, h, d = exr_dump.read(path)
    out = {}
    for k, v in d.items():
        parts = k.split(".")
        layer, ch = ".".join(parts[1:-1]), parts[-1]
        out.setdefault(layer, {})[ch] = np.asarray(v, dtype=np.float64)
    rgb = {}
    for layer, chans in out.items():
        if all(c in chans for c in "RGB"):
            rgb[layer] = np.stack([chans[c] for c in "RGB"], axis=1)
        elif "X" in chans:
            rgb[layer] = chans["X"]
    return rgb


def component(img, light, col):
    if light not in img:
        return None
    return img[light] * (img[col] if col else 1.0)


def top_share(se_px, q=0.001):
    """Share of the squared error in the worst `q` of the pixels."""
    s = np.sort(se_px)[::-1]
    k = max(1, int(round(q * len(s))))
    tot = s.sum()
    return s[:k].sum() / tot if tot > 0 else 0.0


def lum(x):
    return x @ LUM


def main():
    args = sys.argv[1:]
    objects = "--objects" in args
    half = 0.5 if "--pair" in args else 1.0
    args = [a for a in args if a not in ("--objects", "--pair")]
    ref_dir = None
    if "--ref-dir" in args:
        i = args.index("--ref-dir")
        ref_dir = args[i + 1]
        del args[i:i + 2]
    out, ref_tag, tags = args[0], args[1], args[2:]
    for scene in sorted(os.listdir(out)):
        rdir = os.path.join(ref_dir or out, scene)
        rpath = os.path.join(rdir, ref_tag + ".exr")
        if not os.path.exists(rpath):
            continue
        ref = load(rpath)
        rc = ref["Combined"][:, :3]
        rmean = rc.mean()
        print("== %s: reference %s mean lum %.5f albedo lum %.4f" % (
            scene, ref_tag, lum(rc).mean(), lum(ref["BaseCol"]).mean()))
        for tag in tags:
            path = os.path.join(out, scene, tag + ".exr")
            if not os.path.exists(path):
                continue
            img = load(path)
            c = img["Combined"][:, :3]
            se_px = half * ((c - rc) ** 2).sum(axis=1)
            total = se_px.sum()
            rel = np.sqrt(se_px.sum() / c.size) / (rmean if half == 1.0 else 0.5 * (rmean + c.mean()))
            info = {}
            jp = os.path.join(out, scene, tag + ".json")
            if os.path.exists(jp):
                with open(jp) as f:
                    info = json.load(f)
            print("-- %s: rel err %.4f  top0.1%% share %.2f  mean lum %.5f (%.4f of ref)  "
                  "albedo %.4f of ref  %.2f s wall %.2f s cpu (load %.1f)" % (
                      tag, rel, top_share(se_px), lum(c).mean(), lum(c).mean() / lum(rc).mean(),
                      lum(img["BaseCol"]).mean() / lum(ref["BaseCol"]).mean(),
                      info.get("wall_s", 0), info.get("cpu_s", 0), info.get("load", 0)))
            for light, col in COMPONENTS:
                a, b = component(img, light, col), component(ref, light, col)
                if a is None or b is None:
                    continue
                se = half * ((a - b) ** 2).sum(axis=1)
                rl = lum(b).mean()
                if rl <= 0 and se.sum() == 0:
                    continue
                print("   %-9s se share %6.3f  top0.1%% %.2f  mean %.5f / ref %.5f (%.4f)" % (
                    light, se.sum() / max(total, 1e-30), top_share(se), lum(a).mean(), rl,
                    lum(a).mean() / rl if rl > 0 else float("nan")))
            cols = ["%s %.4f" % (col, lum(img[col]).mean() / max(1e-12, lum(ref[col]).mean()))
                    for col in ("DiffCol", "GlossCol", "TransCol") if col in img]
            print("   colours vs ref: " + ", ".join(cols))
            if objects:
                idx = np.rint(ref["IndexOB"]).astype(int)
                for o in np.unique(idx):
                    m = idx == o
                    print("   object %2d: %5.1f%% of pixels, %5.1f%% of squared error, "
                          "mean lum %.4f of ref" % (
                              o, 100 * m.mean(), 100 * se_px[m].sum() / total,
                              lum(c[m]).mean() / max(1e-12, lum(rc[m]).mean())))


main()
