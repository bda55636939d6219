"""Generate the `clevrtex eval` fixtures in this folder (committed; tests never run Python).

    python3 -m venv /tmp/v && /tmp/v/bin/pip install numpy scipy scikit-learn pillow
    /tmp/v/bin/python tests/data/eval/make_fixtures.py

Expected values come from scipy's `linear_sum_assignment`, scikit-learn's
`adjusted_rand_score` and Pillow's resize, i.e. the calls the public evaluator makes per image,
re-implemented here with numpy (no PyTorch) following docs/eval.md.
"""

import json
import os
import zipfile

import numpy as np
from PIL import Image
from scipy.optimize import linear_sum_assignment
from sklearn.metrics import adjusted_rand_score

HERE = os.path.dirname(os.path.abspath(__file__))
rng = np.random.default_rng(20211206)


def reference_scores(truth, pred_hard, k_pred, truth_rgb=None, pred_rgb=None):
    """Per-image metrics of the public evaluator (spec semantics), numpy + scipy + sklearn."""
    truth = truth.astype(np.int64).ravel()
    pred = pred_hard.astype(np.int64).ravel()
    k = int(max(truth.max() + 1, pred.max() + 1, k_pred))
    t1 = np.eye(k, dtype=bool)[truth].T  # (k, n)
    p1 = np.eye(k, dtype=bool)[pred].T
    inter = (p1[:, None, :] & t1[None, :, :]).sum(-1)  # [p][t]
    union = (p1[:, None, :] | t1[None, :, :]).sum(-1)
    iou = np.where(union > 0, inter.astype(np.float32) / np.maximum(union, 1).astype(np.float32), 0).astype(np.float32)
    empty = (p1.sum(1)[:, None] == 0) | (t1.sum(1)[None, :] == 0)
    iou[empty] = 0
    rows, cols = linear_sum_assignment(iou.T.astype(np.float64), maximize=True)
    sigma = cols  # rows are 0..k-1 in order
    iou_t = np.array([iou[sigma[t], t] for t in range(k)], dtype=np.float64)
    tsz = t1.sum(1)
    psz = p1.sum(1)
    nonempty = np.array([tsz[t] > 0 or psz[sigma[t]] > 0 for t in range(k)])
    num_pairs = int(nonempty.sum())
    dice_t = np.array(
        [2 * inter[sigma[t], t] / (psz[sigma[t]] + tsz[t]) if psz[sigma[t]] + tsz[t] > 0 else 0.0 for t in range(k)]
    )
    out = {
        "mIoU": iou_t.sum() / num_pairs,
        "mIoU_fg": iou_t[1:].sum() / (num_pairs - 1) if num_pairs > 1 else None,
        "mIoU_gt": iou_t.sum() / (tsz > 0).sum(),
        "ARI": adjusted_rand_score(truth, pred),
        "ARI_FG": adjusted_rand_score(truth[truth > 0], pred[truth > 0]) if (truth > 0).any() else 1.0,
        "DICE": dice_t.sum() / num_pairs,
        "DICE_fg": dice_t[1:].sum() / (num_pairs - 1) if num_pairs > 1 else None,
        "acc": float((tsz > 0).sum() == (psz > 0).sum()),
        "mSC": float(sum(tsz[t] * iou[:, t].max() for t in range(k) if tsz[t] > 0) / tsz.sum()),
        "num_pairs": num_pairs,
    }
    if truth_rgb is not None:
        d = pred_rgb.astype(np.float32) - (truth_rgb.astype(np.float32) / np.float32(255))
        out["MSE"] = float((d * d).astype(np.float64).sum())
    return {k: (float(v) if v is not None else None) for k, v in out.items()}


def lsa_ties():
    cases = []
    for i in range(300):
        n = int(rng.integers(1, 9))
        levels = int(rng.integers(1, 4))
        cost = rng.integers(0, levels + 1, size=(n, n)) / levels
        if i % 3 == 0:
            cost[:, rng.integers(0, n)] = 0  # empty columns, as empty slots give
        r, c = linear_sum_assignment(-cost.astype(np.float64))
        cases.append({"n": n, "cost": (-cost).ravel().tolist(), "assignment": c.tolist()})
    with open(os.path.join(HERE, "lsa_ties.json"), "w") as f:
        json.dump(cases, f)


def crop_box(w, h):
    c = int(0.8 * min(w, h))
    return ((w - c) // 2, (h - c) // 2, (w + c) // 2, (h + c) // 2), c


def nearest(mask, out=128):
    h, w = mask.shape
    (x0, y0, _, _), c = crop_box(w, h)
    idx = ((2 * np.arange(out) + 1) * c) // (2 * out)
    return mask[y0 + idx][:, x0 + idx]


def resize_fixtures():
    d = os.path.join(HERE, "resize")
    os.makedirs(d, exist_ok=True)
    for w, h in [(320, 240), (101, 77), (40, 30), (160, 160), (123, 201)]:
        # Smooth gradients plus noise: both large and single-step differences matter.
        yy, xx = np.mgrid[0:h, 0:w]
        base = np.stack([xx * 255 / max(w - 1, 1), yy * 255 / max(h - 1, 1), (xx + yy) % 256], -1)
        img = np.clip(base + rng.integers(-6, 7, size=(h, w, 3)), 0, 255).astype(np.uint8)
        im = Image.fromarray(img, "RGB")
        im.save(os.path.join(d, f"in_{w}x{h}.png"))
        box, _ = crop_box(w, h)
        im.crop(box).resize((128, 128), Image.BILINEAR).save(os.path.join(d, f"out_{w}x{h}.png"))
        # The spec's nearest formula against Pillow's NEAREST on a mask.
        m = rng.integers(0, 11, size=(h, w)).astype(np.uint8)
        pil = np.asarray(Image.fromarray(m, "L").crop(box).resize((128, 128), Image.NEAREST))
        if not (pil == nearest(m)).all():
            print(f"note: Pillow NEAREST differs from the spec formula at {w}x{h}: {(pil != nearest(m)).mean():.4f}")


def random_case(h, w, kt, kp, soft):
    truth = rng.integers(0, kt, size=(h, w))
    if rng.random() < 0.5:
        # Blocky truth: larger segments, as real masks have.
        truth = np.kron(rng.integers(0, kt, size=(h // 2, w // 2)), np.ones((2, 2), dtype=np.int64))
    if soft:
        masks = rng.random((kp, h, w)).astype(np.float32)
        masks[rng.random((kp, h, w)) < 0.1] = 0.5  # ties
        pred = np.argmax(masks, 0)
        return truth, pred, masks
    pred = rng.integers(0, kp, size=(h, w))
    if rng.random() < 0.5:
        # A relabelled copy of the truth with some noise: matching ties and near-ties.
        perm = rng.permutation(max(kt, kp))
        pred = np.where(rng.random((h, w)) < 0.2, pred, perm[truth] % kp)
    return truth, pred, None


def reference_cases():
    cases = []
    for i in range(200):
        h, w = int(rng.integers(1, 4)) * 4, int(rng.integers(1, 4)) * 4
        kt, kp = int(rng.integers(1, 7)), int(rng.integers(1, 8))
        truth, pred, _ = random_case(h, w, kt, kp, soft=False)
        cases.append(
            {
                "h": h,
                "w": w,
                "truth": truth.ravel().tolist(),
                "pred": pred.ravel().tolist(),
                "k_pred": kp,
                "expected": reference_scores(truth, pred, kp),
            }
        )
    with open(os.path.join(HERE, "reference_cases.json"), "w") as f:
        json.dump(cases, f)


def save_npz(path, **arrays):
    np.savez_compressed(path, **arrays)


def dataset():
    """10 small samples (40x30) in the published layout, predictions in three formats, and the
    expected per-image metrics under the clevrtex protocol."""
    root = os.path.join(HERE, "gt", "clevrtex_vbg", "0")
    os.makedirs(root, exist_ok=True)
    pdirs = {k: os.path.join(HERE, "preds", k) for k in ["png", "npz", "npy"]}
    for d in pdirs.values():
        os.makedirs(d, exist_ok=True)
    materials = ["rope", "moss", "denim"]
    shapes = ["cube", "sphere", "cylinder", "monkey"]
    expected = []
    palette = sum(([(i * 40) % 256, (i * 90) % 256, (i * 150) % 256] for i in range(256)), [])
    for idx in range(10):
        stem = f"CLEVRTEX_vbg_{idx:06d}"
        h, w = 30, 40
        n_obj = int(rng.integers(1, 5))
        mask = np.zeros((h, w), dtype=np.uint8)
        objects = []
        for o in range(n_obj):
            y, x = int(rng.integers(0, h - 8)), int(rng.integers(0, w - 8))
            mask[y : y + int(rng.integers(4, 9)), x : x + int(rng.integers(4, 9))] = o + 1
            objects.append(
                {
                    "material": materials[int(rng.integers(0, 3))],
                    "shape": shapes[int(rng.integers(0, 4))],
                    "size": ["small", "medium", "large"][int(rng.integers(0, 3))],
                    "color": ["red", "blue"][int(rng.integers(0, 2))],
                    "index": o,
                }
            )
        if idx == 3:
            mask[:, :4] = n_obj  # partly outside the crop
        yy, xx = np.mgrid[0:h, 0:w]
        img = np.stack([xx * 6, yy * 8, 60 + 40 * mask], -1) + rng.integers(-20, 21, size=(h, w, 3))
        img = np.clip(img, 0, 255).astype(np.uint8)
        Image.fromarray(img, "RGB").save(os.path.join(root, stem + ".png"))
        pm = Image.fromarray(mask, "P")
        pm.putpalette(palette)
        pm.save(os.path.join(root, stem + "_flat.png"))
        meta = {"image_index": idx, "num_objects": n_obj, "ground_material": materials[idx % 3], "objects": objects}
        with open(os.path.join(root, stem + ".json"), "w") as f:
            json.dump(meta, f)

        truth = nearest(mask)
        box, _ = crop_box(w, h)
        truth_rgb = np.asarray(Image.fromarray(img, "RGB").crop(box).resize((128, 128), Image.BILINEAR))
        kp = n_obj + 2
        masks = rng.random((kp, 128, 128)).astype(np.float32)
        # Make the soft masks mostly right: boost the true slot under a random permutation.
        perm = rng.permutation(kp)
        boost = np.eye(kp, dtype=np.float32)[perm[np.minimum(truth, kp - 1)]].transpose(2, 0, 1)
        masks = masks + 1.5 * boost * (rng.random((128, 128)) < 0.9)
        masks = (np.floor(masks * 4) / 4).astype(np.float32)  # coarse: compresses, and ties
        pred = np.argmax(masks, 0)
        recon = np.clip(truth_rgb / 255 + rng.normal(0, 0.1, size=truth_rgb.shape) * (rng.random((128, 128, 1)) < 0.2), 0, 1).astype(np.float32)
        recon = (np.round(recon * 64) / 64).astype(np.float32)
        recon8 = np.round(recon * 255).astype(np.uint8)
        Image.fromarray(pred.astype(np.uint8), "L").save(os.path.join(pdirs["png"], stem + "_mask.png"))
        Image.fromarray(recon8, "RGB").save(os.path.join(pdirs["png"], stem + "_recon.png"))
        save_npz(os.path.join(pdirs["npz"], stem + ".npz"), masks=masks, recon=recon.transpose(2, 0, 1))
        np.save(os.path.join(pdirs["npy"], stem + ".npy"), pred.astype(np.uint8 if idx % 2 else ">i2"))
        e_png = reference_scores(truth, pred, int(pred.max()) + 1, truth_rgb, recon8.astype(np.float32) / np.float32(255))
        e_npz = reference_scores(truth, pred, kp, truth_rgb, recon)
        expected.append({"index": idx, "png": e_png, "npz": e_npz})
    with open(os.path.join(HERE, "dataset_expected.json"), "w") as f:
        json.dump(expected, f, indent=1)


def fuzz_corpus():
    """Small valid seeds the fuzz tests mutate (crates/eval/tests/fuzz.rs)."""
    d = os.path.join(HERE, "fuzz")
    os.makedirs(d, exist_ok=True)
    m = rng.integers(0, 4, size=(6, 5)).astype(np.uint8)
    p = Image.fromarray(m, "P")
    p.putpalette([0, 0, 0, 255, 0, 0, 0, 255, 0, 0, 0, 255] * 64)
    p.save(os.path.join(d, "palette.png"))
    Image.fromarray(m.astype(np.uint16) * 300).save(os.path.join(d, "grey16.png"))
    Image.fromarray(m > 1).save(os.path.join(d, "bit1.png"))
    Image.fromarray(rng.integers(0, 256, size=(4, 3, 3)).astype(np.uint8), "RGB").save(os.path.join(d, "rgb.png"))
    Image.fromarray(rng.integers(0, 256, size=(4, 3, 4)).astype(np.uint8), "RGBA").save(os.path.join(d, "rgba.png"))
    np.save(os.path.join(d, "labels_i4.npy"), m.astype(np.int32))
    np.save(os.path.join(d, "masks_f4.npy"), rng.random((3, 6, 5)).astype(np.float32))
    f8 = rng.random((2, 3, 4))
    np.save(os.path.join(d, "masks_f8_fortran.npy"), np.asfortranarray(f8))
    np.save(os.path.join(d, "masks_f8_big_endian.npy"), f8.astype(">f8"))
    np.save(os.path.join(d, "half.npy"), rng.random((2, 2)).astype(np.float16))
    np.savez(os.path.join(d, "stored.npz"), labels=m)
    np.savez_compressed(os.path.join(d, "deflated.npz"), masks=rng.random((2, 6, 5)).astype(np.float32), recon=rng.random((3, 6, 5)))
    with open(os.path.join(d, "meta.json"), "w") as f:
        json.dump({"ground_material": "moss", "objects": [{"material": "rope", "shape": "cube", "size": "large", "color": "red"}]}, f)


if __name__ == "__main__":
    fuzz_corpus()
    lsa_ties()
    resize_fixtures()
    reference_cases()
    dataset()
