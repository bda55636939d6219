"""Per-image cost of the public ClevrTex evaluator, re-implemented with numpy + scipy +
scikit-learn (PyTorch is not installed here; the public class makes these same per-image
calls: Pillow load/crop/resize, one-hot masks, an IoU matrix, scipy's
`linear_sum_assignment`, scikit-learn's `adjusted_rand_score` twice, MSE, mSC and the
per-object loop). It is a timing stand-in, not a second implementation to trust for values.

    /tmp/v/bin/python crates/eval/examples/public_eval_numpy.py /tmp/evalbench 500
"""

import glob
import json
import os
import sys
import time

import numpy as np
from PIL import Image
from scipy.optimize import linear_sum_assignment
from sklearn.metrics import adjusted_rand_score


def crop_box(w, h):
    c = int(0.8 * min(w, h))
    return ((w - c) // 2, (h - c) // 2, (w + c) // 2, (h + c) // 2)


def load_gt(stem_path):
    img = Image.open(stem_path + ".png").convert("RGB")
    box = crop_box(*img.size)
    img = np.asarray(img.crop(box).resize((128, 128), Image.BILINEAR), dtype=np.float32) / 255
    mask = Image.open(stem_path + "_flat.png")
    mask = np.asarray(mask.crop(box).resize((128, 128), Image.NEAREST)).astype(np.int64)
    with open(stem_path + ".json") as f:
        meta = json.load(f)
    return img.transpose(2, 0, 1), mask, meta


def evaluate_one(true_img, true_mask, meta, pred_img, pred_mask):
    k = int(max(true_mask.max() + 1, pred_mask.max() + 1))
    t1 = np.eye(k, dtype=np.float32)[true_mask.ravel()].T  # one-hot (K, N)
    p1 = np.eye(k, dtype=np.float32)[pred_mask.ravel()].T
    inter = p1 @ t1.T
    union = p1.sum(1)[:, None] + t1.sum(1)[None, :] - inter
    iou = np.where(union > 0, inter / np.maximum(union, 1), 0).astype(np.float32)
    _, cols = linear_sum_assignment(iou.T, maximize=True)
    iou_t = iou[cols, np.arange(k)]
    mse = float(((pred_img - true_img) ** 2).sum())
    t = true_mask.ravel()
    p = pred_mask.ravel()
    ari = adjusted_rand_score(t, p)
    fg = t > 0
    ari_fg = adjusted_rand_score(t[fg], p[fg])
    sizes = t1.sum(1)
    msc = float((sizes * iou.max(0)).sum() / sizes.sum())
    per_obj = {}
    for i, o in enumerate(meta["objects"]):
        if sizes[i + 1] > 0 if i + 1 < k else False:
            per_obj.setdefault(o["material"], []).append(float(iou_t[i + 1]))
    return mse, ari, ari_fg, msc, iou_t.mean(), per_obj


def main():
    root = sys.argv[1]
    n = int(sys.argv[2]) if len(sys.argv) > 2 else 500
    stems = sorted(glob.glob(os.path.join(root, "gt", "**", "CLEVRTEX_*_??????.png"), recursive=True))[:n]
    t0 = time.perf_counter()
    for s in stems:
        stem_path = s[: -len(".png")]
        name = os.path.basename(stem_path)
        pdir = os.path.join(root, "preds", os.path.basename(os.path.dirname(stem_path)))
        true_img, true_mask, meta = load_gt(stem_path)
        pred_mask = np.asarray(Image.open(os.path.join(pdir, name + "_mask.png"))).astype(np.int64)
        pred_img = np.asarray(Image.open(os.path.join(pdir, name + "_recon.png")).convert("RGB"), dtype=np.float32).transpose(2, 0, 1) / 255
        evaluate_one(true_img, true_mask, meta, pred_img, pred_mask)
    dt = time.perf_counter() - t0
    print(f"images: {len(stems)}, {dt:.2f} s, {len(stems) / dt:.1f} images/s (one process)")


if __name__ == "__main__":
    main()
