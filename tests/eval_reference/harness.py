"""Reference harness for `clevrtex eval`'s protocols (run by tests/eval_protocols.rs and the
Python package's tests; needs numpy, scipy, scikit-learn and Pillow: `.venv-test`).

The three public evaluators are re-written here in numpy, statement by statement, from their
published sources (read, not copied):

- `deepmind/multi_object_datasets` `segmentation_metrics.py`: `adjusted_rand_index`
  (TensorFlow; float32 there, float64 here: `dtype=` switches, see `dm_adjusted_rand_index`).
- `amazon-science/object-centric-learning-framework` `ocl/metrics/utils.py`
  (`adjusted_rand_index`, `fg_adjusted_rand_index`, `tensor_to_one_hot`) and
  `ocl/metrics/masks.py` (`ARIMetric.update`, `UnsupervisedMaskIoUMetric.update`,
  `unsupervised_mask_iou`; torch float64 there, numpy float64 here).
- `karazijal/clevrtex` `clevrtex_eval.py`: `CLEVRTEX` (the loader: its index of a variant's
  files and split by position, crop, Pillow resize) and `CLEVRTEX_Evaluator.update` /
  `statistic` (torch there, numpy here).

Why numpy and not the originals: the originals need TensorFlow or PyTorch; PyPI's Linux
PyTorch wheel (torch 2.15.0, 539 MB) pulls the CUDA 13 libraries (cuDNN, NCCL, cuSPARSELt,
NVSHMEM, the CUDA toolkit, Triton: several GB) and PyPI has no CPU-only build, which is too
much for CI. Every torch/tf call used maps to a numpy call with the same semantics (argmax:
first index on ties; float64 sums of integer counts are exact).

Usage:
    python harness.py cases OUT.json             # per-image fixtures with expected values
    python harness.py dataset GT PREDS OUT.json  # per-protocol means over a dataset (npz preds)
    python harness.py splits ROOT OUT.json       # the public loader's indices per variant and split
"""

import json
import os
import pathlib
import sys
from collections import defaultdict

import numpy as np
from PIL import Image
from scipy.optimize import linear_sum_assignment
from sklearn.metrics import adjusted_rand_score

# ---------------------------------------------------------------------------------------------
# deepmind/multi_object_datasets: segmentation_metrics.adjusted_rand_index


def _all_equal(values):
    return np.all(values == values[..., :1], axis=-1)


def dm_adjusted_rand_index(true_mask, pred_mask, dtype=np.float64):
    """true_mask (B, N, G) one-hot (rows of zeros are ignored), pred_mask (B, N, P)."""
    _, n_points, n_true_groups = true_mask.shape
    n_pred_groups = pred_mask.shape[-1]
    if n_points <= n_true_groups and n_points <= n_pred_groups:
        raise ValueError("adjusted_rand_index requires n_groups < n_points")
    true_group_ids = np.argmax(true_mask, -1)
    pred_group_ids = np.argmax(pred_mask, -1)
    true_mask_oh = true_mask.astype(dtype)
    pred_mask_oh = np.eye(n_pred_groups, dtype=dtype)[pred_group_ids]
    n_points = np.sum(true_mask_oh, axis=(1, 2)).astype(dtype)
    nij = np.einsum("bji,bjk->bki", pred_mask_oh, true_mask_oh)
    a = np.sum(nij, axis=1)
    b = np.sum(nij, axis=2)
    with np.errstate(divide="ignore", invalid="ignore"):
        rindex = np.sum(nij * (nij - 1), axis=(1, 2))
        aindex = np.sum(a * (a - 1), axis=1)
        bindex = np.sum(b * (b - 1), axis=1)
        expected_rindex = aindex * bindex / (n_points * (n_points - 1))
        max_rindex = (aindex + bindex) / 2
        ari = (rindex - expected_rindex) / (max_rindex - expected_rindex)
    both_single_cluster = np.logical_and(_all_equal(true_group_ids), _all_equal(pred_group_ids))
    return np.where(both_single_cluster, np.ones_like(ari), ari)


# ---------------------------------------------------------------------------------------------
# amazon-science/object-centric-learning-framework: ocl/metrics/utils.py


def ocl_tensor_to_one_hot(tensor, dim):
    max_idxs = np.argmax(tensor, axis=dim)
    max_idxs = np.expand_dims(max_idxs, dim)
    shape = [1] * dim + [-1] + [1] * (tensor.ndim - dim - 1)
    one_hot = max_idxs == np.arange(tensor.shape[dim]).reshape(*shape)
    return one_hot.astype(np.int64)


def ocl_adjusted_rand_index(pred_mask, true_mask):
    n_pred_clusters = pred_mask.shape[-1]
    pred_cluster_ids = np.argmax(pred_mask, axis=-1)
    true_mask_oh = true_mask.astype(np.float64)
    pred_mask_oh = np.eye(n_pred_clusters, dtype=np.float64)[pred_cluster_ids]
    n_ij = np.einsum("bnc,bnk->bck", true_mask_oh, pred_mask_oh)
    a = np.sum(n_ij, axis=-1)
    b = np.sum(n_ij, axis=-2)
    n_fg_points = np.sum(a, axis=1)
    rindex = np.sum(n_ij * (n_ij - 1), axis=(1, 2))
    aindex = np.sum(a * (a - 1), axis=1)
    bindex = np.sum(b * (b - 1), axis=1)
    expected_rindex = aindex * bindex / np.clip(n_fg_points * (n_fg_points - 1), 1, None)
    max_rindex = (aindex + bindex) / 2
    denominator = max_rindex - expected_rindex
    with np.errstate(divide="ignore", invalid="ignore"):
        ari = (rindex - expected_rindex) / denominator
    return np.where(denominator > 0, ari, np.ones_like(ari))


def ocl_fg_adjusted_rand_index(pred_mask, true_mask, bg_dim=0):
    n_true_clusters = true_mask.shape[-1]
    assert 0 <= bg_dim < n_true_clusters
    if bg_dim == 0:
        true_mask_only_fg = true_mask[..., 1:]
    elif bg_dim == n_true_clusters - 1:
        true_mask_only_fg = true_mask[..., :-1]
    else:
        true_mask_only_fg = np.concatenate((true_mask[..., :bg_dim], true_mask[..., bg_dim + 1 :]), -1)
    return ocl_adjusted_rand_index(pred_mask, true_mask_only_fg)


# ocl/metrics/masks.py


def ocl_ari_metric_update(prediction, target, foreground=True, convert_target_one_hot=False, ignore_overlaps=False):
    """ARIMetric.update on (B, C, H, W) / (B, K, H, W); returns the per-image ARI (B,)."""
    prediction = prediction.reshape(*prediction.shape[:2], -1)
    target = target.reshape(*target.shape[:2], -1)
    ignore = None
    if ignore_overlaps:
        ignore = (target > 0).sum(1, keepdims=True) > 1
    if ignore is not None:
        prediction = prediction.copy()
        prediction[np.broadcast_to(ignore, prediction.shape)] = 0
        target = target.copy()
        target[np.broadcast_to(ignore, target.shape)] = 0
    prediction = np.swapaxes(prediction, -2, -1)
    target = np.swapaxes(target, -2, -1)
    if convert_target_one_hot:
        target_oh = ocl_tensor_to_one_hot(target, dim=2)
        target_oh[:, :, 0][target.sum(axis=2) == 0] = 0
        target = target_oh
    assert np.all(target.sum(axis=-1) < 2), "Issues with target format, mask non-exclusive"
    if foreground:
        return ocl_fg_adjusted_rand_index(prediction, target)
    return ocl_adjusted_rand_index(prediction, target)


def ocl_unsupervised_mask_iou(pred_mask, true_mask, matching="hungarian", iou_empty=0.0):
    """Per-class IoU (reduction="none") of pred (C, N) against true (K, N)."""
    n_gt_classes = len(true_mask)
    pred_mask = pred_mask[:, None].astype(bool)
    true_mask = true_mask[None].astype(bool)
    intersection = np.sum(pred_mask & true_mask, axis=-1).astype(np.float64)
    union = np.sum(pred_mask | true_mask, axis=-1).astype(np.float64)
    with np.errstate(divide="ignore", invalid="ignore"):
        pairwise_iou = intersection / union
    pairwise_iou[union == 0] = iou_empty
    if matching == "hungarian":
        pred_idxs, true_idxs = linear_sum_assignment(pairwise_iou, maximize=True)
    elif matching == "best_overlap":
        non_empty_gt = np.sum(true_mask[0], axis=1) > 0
        pred_idxs = np.argmax(pairwise_iou, axis=0)[non_empty_gt]
        true_idxs = np.arange(pairwise_iou.shape[1])[non_empty_gt]
    else:
        raise ValueError(matching)
    matched_iou = pairwise_iou[pred_idxs, true_idxs]
    iou = np.zeros(n_gt_classes, dtype=np.float64)
    iou[true_idxs] = matched_iou
    return iou


def ocl_mask_iou_metric_update(
    prediction,
    target,
    matching="hungarian",
    ignore_background=False,
    ignore_overlaps=False,
    correct_localization=False,
    discovery_threshold=0.5,
):
    """UnsupervisedMaskIoUMetric.update; returns one value per image, None where the
    original skips the image (no non-empty target class)."""
    predictions = prediction.reshape(*prediction.shape[:2], -1)
    targets = target.reshape(*target.shape[:2], -1)
    indices = np.argmax(predictions, axis=1)
    predictions = np.eye(predictions.shape[1], dtype=np.int64)[indices]  # (B, N, C)
    predictions = np.swapaxes(predictions, 1, 2)
    if ignore_background:
        targets = targets[:, 1:]
    targets = targets > 0
    ignore = None
    if ignore_overlaps:
        ignore = targets.sum(1, keepdims=True) > 1
    if ignore is not None:
        predictions[np.broadcast_to(ignore, predictions.shape)] = 0
        targets[np.broadcast_to(ignore, targets.shape)] = 0
    assert np.all(targets.sum(axis=1) < 2)
    out = []
    for pred, tgt in zip(predictions, targets):
        nonzero_classes = np.sum(tgt, axis=-1) > 0
        tgt = tgt[nonzero_classes]
        if len(tgt) == 0:
            out.append(None)
            continue
        iou_per_class = ocl_unsupervised_mask_iou(pred, tgt, matching=matching)
        if correct_localization:
            out.append(float(np.any(iou_per_class > discovery_threshold)))
        else:
            out.append(float(iou_per_class.mean()))
    return out


# ---------------------------------------------------------------------------------------------
# Our metric names -> the originals, on one image given as labels.


def one_hot(labels, k):
    """(H, W) ids -> (1, k, H, W)."""
    return (labels[None, None] == np.arange(k)[None, :, None, None]).astype(np.float64)


def protocol_metrics(truth, pred_probs):
    """truth (H, W) ids; pred_probs (P, H, W) per-slot scores (argmax taken by each original)."""
    h, w = truth.shape
    kt = int(truth.max()) + 1
    target = one_hot(truth, max(kt, 2))
    prediction = pred_probs[None].astype(np.float64)
    out = {}
    # DeepMind: true one-hot without the background column; background rows all zero.
    t = target[:, 1:].reshape(1, -1, h * w).transpose(0, 2, 1)
    p = prediction.reshape(1, prediction.shape[1], -1).transpose(0, 2, 1)
    try:
        v = float(dm_adjusted_rand_index(t, p)[0])
        out["dm_FG_ARI"] = v if np.isfinite(v) else None
    except ValueError:
        out["dm_FG_ARI"] = "refused"
    kw = dict(convert_target_one_hot=True, ignore_overlaps=True)
    out["ocl_ARI"] = float(ocl_ari_metric_update(prediction, target, foreground=False, **kw)[0])
    out["ocl_FG_ARI"] = float(ocl_ari_metric_update(prediction, target, foreground=True, **kw)[0])
    iou = dict(ignore_overlaps=True)
    out["ocl_mIoU"] = ocl_mask_iou_metric_update(prediction, target, "hungarian", **iou)[0]
    out["ocl_mIoU_fg"] = ocl_mask_iou_metric_update(prediction, target, "hungarian", ignore_background=True, **iou)[0]
    out["mBO"] = ocl_mask_iou_metric_update(prediction, target, "best_overlap", ignore_background=True, **iou)[0]
    out["CorLoc"] = ocl_mask_iou_metric_update(
        prediction, target, "best_overlap", ignore_background=True, correct_localization=True, **iou
    )[0]
    return out


# ---------------------------------------------------------------------------------------------
# Fixtures.

rng = np.random.default_rng(20261123)


def labels_to_probs(pred, k):
    return (pred[None] == np.arange(k)[:, None, None]).astype(np.float32)


def case(name, truth, probs):
    truth = np.asarray(truth, dtype=np.int64)
    h, w = truth.shape
    return {
        "name": name,
        "h": h,
        "w": w,
        "truth": truth.ravel().tolist(),
        "k": int(probs.shape[0]),
        "masks": probs.astype(np.float32).ravel().tolist(),
        "expected": protocol_metrics(truth, probs),
    }


def blocky(h, w, k):
    t = rng.integers(0, k, size=(h // 2, w // 2))
    return np.kron(t, np.ones((2, 2), dtype=np.int64))


def make_cases():
    cases = []
    # Random, with relabelled-and-noisy predictions: matching ties and near-ties.
    for i in range(120):
        h, w = int(rng.integers(2, 5)) * 4, int(rng.integers(2, 5)) * 4
        kt, kp = int(rng.integers(1, 7)), int(rng.integers(1, 8))
        truth = blocky(h, w, kt) if i % 2 else rng.integers(0, kt, size=(h, w))
        pred = rng.integers(0, kp, size=(h, w))
        if i % 3:
            perm = rng.permutation(max(kt, kp))
            pred = np.where(rng.random((h, w)) < 0.2, pred, perm[truth] % kp)
        cases.append(case(f"random_{i}", truth, labels_to_probs(pred, kp)))
    # Ties: two predicted slots that split an object evenly; a prediction that is a relabelled
    # copy with empty slots in between.
    truth = np.zeros((8, 8), dtype=np.int64)
    truth[2:6, 2:6] = 1
    pred = truth.copy()
    pred[2:6, 2:4] = 2
    cases.append(case("tie_even_split", truth, labels_to_probs(pred, 3)))
    cases.append(case("empty_slots", truth, labels_to_probs(truth * 4, 7)))
    # One object: predicted whole (DeepMind's 0/0), merged with the background, split.
    cases.append(case("one_object_perfect", truth, labels_to_probs(truth, 2)))
    cases.append(case("one_object_merged", truth, labels_to_probs(np.zeros_like(truth), 2)))
    cases.append(case("one_object_split", truth, labels_to_probs(pred, 3)))
    # All background: predicted as one slot and as several.
    bg = np.zeros((8, 8), dtype=np.int64)
    cases.append(case("all_background_one_slot", bg, labels_to_probs(bg, 1)))
    cases.append(case("all_background_split", bg, labels_to_probs(blocky(8, 8, 3), 3)))
    # One object pixel.
    px = bg.copy()
    px[4, 4] = 1
    cases.append(case("one_pixel", px, labels_to_probs(rng.integers(0, 3, size=(8, 8)), 3)))
    # 300 segments: a relabelled copy, and pairs merged.
    truth = (np.arange(40 * 40).reshape(40, 40) // 5) % 300
    cases.append(case("segments_300_relabelled", truth, labels_to_probs((truth * 7 + 3) % 300, 300)))
    cases.append(case("segments_300_merged", truth, labels_to_probs(truth // 2, 300)))
    # Soft masks with ties (argmax takes the first) and a soft 300-slot case.
    for i in range(20):
        h, w = 8, 12
        kt, kp = int(rng.integers(1, 6)), int(rng.integers(2, 8))
        truth = blocky(h, w, kt)
        masks = rng.random((kp, h, w)).astype(np.float32)
        masks[rng.random((kp, h, w)) < 0.3] = 0.5
        masks[:, 0, :] = 0.25  # a whole row tied across slots
        cases.append(case(f"soft_{i}", truth, masks))
    return cases


# ---------------------------------------------------------------------------------------------
# karazijal/clevrtex: the `CLEVRTEX` loader's crop and resize (Pillow), for datasets.


def clevrtex_load(img_path, msk_path, crop=True, resize=(128, 128)):
    img = Image.open(img_path)
    msk = Image.open(msk_path)
    if crop:
        c = int(0.8 * float(min(img.width, img.height)))
        box = lambda im: ((im.width - c) // 2, (im.height - c) // 2, (im.width + c) // 2, (im.height + c) // 2)
        img = img.crop(box(img))
        msk = msk.crop(box(msk))
    if resize:
        img = img.resize(resize, resample=Image.BILINEAR)
        msk = msk.resize(resize, resample=Image.NEAREST)
    img = np.array(img)[..., :3].astype(np.float32).transpose(2, 0, 1) / np.float32(255)
    return img, np.array(msk).astype(np.int64)


# The loader's variants and split fractions (`CLEVRTEX.variants`, `CLEVRTEX.splits`).
PUBLIC_VARIANTS = ["full", "pbg", "vbg", "grassbg", "camo", "outd"]
PUBLIC_SPLITS = {"test": (0.0, 0.1), "val": (0.1, 0.2), "train": (0.2, 1.0)}


def public_split_indices(root, variant, split):
    """The image indices `CLEVRTEX(root, variant, split)` serves, in its order: `_reindex`
    (every `CLEVRTEX_{variant}_??????.png` below `root/clevrtex_{variant}` (or `root` when it is
    that folder), the index parsed from the name, a gap or a duplicate refused), then the split
    by position over all the images: `bias, limit = int(frac * len(index))`; `outd` has no
    split (every image)."""
    base = pathlib.Path(root)
    sub = f"clevrtex_{variant.lower()}"
    if base.name != sub:
        base = base / sub
    prefix = f"CLEVRTEX_{variant}_"
    index = {}
    top = 0
    for img in base.glob(f"**/{prefix}??????.png"):
        digits = img.name.replace(prefix, "").replace(".png", "")
        ind = int(digits) if digits.lstrip("0") else 0
        top = max(top, ind)
        if not (img.parent / f"{prefix}{digits}_flat.png").exists():
            raise ValueError(f"missing mask of {img.name}")
        if ind in index:
            raise ValueError(f"duplicate {ind}")
        index[ind] = img
    if not index:
        raise ValueError("no values found")
    missing = [i for i in range(0, top) if i not in index]
    if missing:
        raise ValueError(f"missing image numbers {missing}")
    bias, limit = (0.0, 1.0) if variant == "outd" else PUBLIC_SPLITS[split]
    bias, limit = int(bias * len(index)), int(limit * len(index))
    # `__getitem__(i)` reads `self.index[i + bias]` for `0 <= i < limit - bias`.
    return [i + bias for i in range(limit - bias)]


def public_splits(root):
    """`public_split_indices` for every variant the loader knows that `root` holds."""
    out = {}
    for v in PUBLIC_VARIANTS:
        if (pathlib.Path(root) / f"clevrtex_{v}").is_dir():
            out[v] = {s: public_split_indices(root, v, s) for s in PUBLIC_SPLITS}
    return out


def dataset_means(gt, preds):
    """Per-protocol means over every sample of `gt` with an npz prediction (`masks`)."""
    per = defaultdict(list)
    stems = sorted(f[:-4] for f in os.listdir(preds) if f.endswith(".npz"))
    for stem in stems:
        d = None
        for root, _, files in os.walk(gt):
            if stem + ".png" in files:
                d = root
        _, truth = clevrtex_load(os.path.join(d, stem + ".png"), os.path.join(d, stem + "_flat.png"))
        masks = np.load(os.path.join(preds, stem + ".npz"))["masks"]
        for k, v in protocol_metrics(truth, masks).items():
            if v is not None and v != "refused":
                per[k].append(v)
    return {k: float(np.mean(v)) for k, v in per.items()}


if __name__ == "__main__":
    mode = sys.argv[1]
    if mode == "cases":
        out = make_cases()
        path = sys.argv[2]
    elif mode == "dataset":
        out = dataset_means(sys.argv[2], sys.argv[3])
        path = sys.argv[4]
    elif mode == "splits":
        out = public_splits(sys.argv[2])
        path = sys.argv[3]
    else:
        sys.exit(f"unknown mode {mode}")
    with open(path, "w") as f:
        json.dump(out, f)


# ---------------------------------------------------------------------------------------------
# karazijal/clevrtex: CLEVRTEX_Evaluator, statement by statement (torch there, numpy here).


class _RunningMean:
    def __init__(self):
        self.v = 0.0
        self.n = 0

    def update(self, v, n=1):
        self.v += v * n
        self.n += n

    def value(self):
        return self.v / self.n if self.n else float("nan")


class ClevrTexEvaluator:
    def __init__(self, masks_have_background=True):
        self.masks_have_background = masks_have_background
        self.stats = defaultdict(_RunningMean)
        self.tags = defaultdict(lambda: defaultdict(lambda: defaultdict(_RunningMean)))

    def ari(self, pred_mask, true_mask, skip_0=False):
        B = pred_mask.shape[0]
        pm = np.squeeze(pred_mask.argmax(axis=1)).reshape(B, -1)
        tm = np.squeeze(true_mask.argmax(axis=1)).reshape(B, -1)
        aris = []
        for bi in range(B):
            t = tm[bi]
            p = pm[bi]
            if skip_0:
                p = p[t > 0]
                t = t[t > 0]
            aris.append(adjusted_rand_score(t, p))
        return np.array(aris)

    def msc(self, pred_mask, true_mask):
        B = pred_mask.shape[0]
        bpm = np.squeeze(pred_mask.argmax(axis=1))
        btm = np.squeeze(true_mask.argmax(axis=1))
        if B == 1:
            bpm, btm = bpm[None], btm[None]
        covering = np.zeros(B, dtype=np.float32)
        for bi in range(B):
            score = 0.0
            norms = 0.0
            for ti in range(btm[bi].max()):
                tm = btm[bi] == ti
                if not np.any(tm):
                    continue
                iou_max = 0.0
                for pi in range(bpm[bi].max()):
                    pm = bpm[bi] == pi
                    if not np.any(pm):
                        continue
                    iou = np.float32((tm & pm).sum()) / np.float32((tm | pm).sum())
                    if iou > iou_max:
                        iou_max = iou
                r = np.float32(tm.sum())
                score += r * iou_max
                norms += r
            covering[bi] = score / norms
        return covering

    def reindex(self, tensor, reindex_tensor, dim=1):
        alignment_index = reindex_tensor.reshape(*reindex_tensor.shape, *([1] * (tensor.ndim - reindex_tensor.ndim)))
        return np.take_along_axis(tensor, np.broadcast_to(alignment_index, tensor.shape), axis=dim)

    def ious_alignment(self, pred_masks, true_masks):
        iou_matrix = np.zeros((pred_masks.shape[0], pred_masks.shape[1], true_masks.shape[1]), dtype=np.float32)
        true_masks_sums = true_masks.sum((-1, -2, -3))
        pred_masks_sums = pred_masks.sum((-1, -2, -3))
        pred_masks = pred_masks.astype(bool)
        true_masks = true_masks.astype(bool)
        with np.errstate(divide="ignore", invalid="ignore"):
            for pi in range(pred_masks.shape[1]):
                pandt = (pred_masks[:, pi : pi + 1] & true_masks).astype(np.float32).sum((-1, -2, -3))
                port = (pred_masks[:, pi : pi + 1] | true_masks).astype(np.float32).sum((-1, -2, -3))
                iou_matrix[:, pi] = pandt / port
                iou_matrix[pred_masks_sums[:, pi] == 0.0, pi] = 0.0
        for ti in range(true_masks.shape[1]):
            iou_matrix[true_masks_sums[:, ti] == 0.0, :, ti] = 0.0
        iou_matrix = np.nan_to_num(iou_matrix, nan=0.0, posinf=0.0, neginf=0.0)
        cost_matrix = iou_matrix
        ious = np.zeros(pred_masks.shape[:2])
        pred_inds = np.zeros(pred_masks.shape[:2], dtype=int)
        for bi in range(cost_matrix.shape[0]):
            true_ind, pred_ind = linear_sum_assignment(cost_matrix[bi].T, maximize=True)
            ious[bi] = cost_matrix[bi].T[true_ind, pred_ind]
            pred_inds[bi] = pred_ind
        return pred_inds, ious, iou_matrix

    def add_statistic(self, name, value, **tags):
        n = 1
        value = np.asarray(value)
        if len(value.shape):
            n = value.shape[0]
            value = np.mean(value)
        value = float(value)
        self.stats[name].update(value, n)
        for k, v in tags.items():
            self.tags[name][k][v].update(value, n)

    def statistic(self, name, tag=None):
        if tag is None:
            return self.stats[name].value()
        return sorted([(k, rm.value()) for k, rm in self.tags[name][tag].items()], key=lambda x: x[1])

    def update(self, pred_image, pred_masks, true_image, true_masks, true_metadata=None):
        assert len(pred_image.shape) == 4
        assert 4 <= len(pred_masks.shape) <= 5
        pred_masks = pred_masks.reshape(pred_image.shape[0], -1, 1, *pred_image.shape[-2:])
        total_pred_masks = pred_masks.sum(1, keepdims=True)
        if not self.masks_have_background:
            pred_masks = np.concatenate([1.0 - total_pred_masks, pred_masks], axis=1)
        K = pred_masks.shape[1]
        pred_masks = pred_masks.argmax(axis=1)
        pred_masks = (pred_masks[:, None] == np.arange(K).reshape(1, -1, 1, 1, 1)).astype(np.float32)
        if len(true_masks.shape) == 4:
            if true_masks.shape[1] == 1:
                true_masks = (
                    true_masks[:, None] == np.arange(max(true_masks.max() + 1, pred_masks.shape[1])).reshape(1, -1, 1, 1, 1)
                ).astype(pred_image.dtype)
            else:
                true_masks = true_masks[:, :, None]
        true_masks = true_masks.reshape(pred_image.shape[0], -1, 1, *pred_image.shape[-2:])
        K = max(true_masks.shape[1], pred_masks.shape[1])
        if true_masks.shape[1] < K:
            pad = np.zeros((true_masks.shape[0], K - true_masks.shape[1], 1, *true_masks.shape[-2:]), true_masks.dtype)
            true_masks = np.concatenate([true_masks, pad], axis=1)
        if pred_masks.shape[1] < K:
            pad = np.zeros((pred_masks.shape[0], K - pred_masks.shape[1], 1, *pred_masks.shape[-2:]), pred_masks.dtype)
            pred_masks = np.concatenate([pred_masks, pad], axis=1)
        # torch sums the float32 squares in float32; float64 here (and in clevrtex), see docs.
        d = (pred_image - true_image).astype(np.float32)
        mse = (d * d).astype(np.float64).sum((1, 2, 3))
        self.add_statistic("MSE", mse)
        pred_count = (pred_masks >= 0.5).any(-1).any(-1).any(-1).astype(np.float32).sum(-1)
        true_count = (true_masks >= 0.5).any(-1).any(-1).any(-1).astype(np.float32).sum(-1)
        self.add_statistic("acc", (true_count == pred_count).astype(np.float32))
        pred_reindex, ious, _ = self.ious_alignment(pred_masks, true_masks)
        pred_masks = self.reindex(pred_masks, pred_reindex, dim=1)
        truem = true_masks.any(-1).any(-1).any(-1)
        predm = pred_masks.any(-1).any(-1).any(-1)
        vism = truem | predm
        num_pairs = vism.astype(np.float32).sum(-1)
        with np.errstate(divide="ignore", invalid="ignore"):
            self.add_statistic("mIoU", ious.sum(-1) / num_pairs)
            self.add_statistic("mIoU_fg", ious[:, 1:].sum(-1) / (num_pairs - 1))
            self.add_statistic("mIoU_gt", ious.sum(-1) / truem.astype(np.float32).sum(-1))
            self.add_statistic("mSC", self.msc(pred_masks, true_masks))
            dices = 2 * (pred_masks * true_masks).sum((-3, -2, -1)) / (pred_masks.sum((-3, -2, -1)) + true_masks.sum((-3, -2, -1)))
        dices = np.nan_to_num(dices, nan=0.0, posinf=0.0)
        with np.errstate(divide="ignore", invalid="ignore"):
            self.add_statistic("DICE", dices.sum(-1) / num_pairs)
            self.add_statistic("DICE_FG", dices[:, 1:].sum(-1) / (num_pairs - 1))
        self.add_statistic("ARI", self.ari(pred_masks, true_masks))
        self.add_statistic("ARI_FG", self.ari(pred_masks, true_masks, skip_0=True))
        if true_metadata is not None:
            d = (pred_image[:, None] * true_masks - true_image[:, None] * true_masks).astype(np.float32)
            smses = (d * d).astype(np.float64).sum((-1, -2, -3))
            for bi, meta in enumerate(true_metadata):
                self.add_statistic("ground_mse", smses[bi, 0], ground_material=meta["ground_material"])
                self.add_statistic("ground_iou", ious[bi, 0], ground_material=meta["ground_material"])
                for i, obj in enumerate(meta["objects"]):
                    tags = {k: v for k, v in obj.items() if k != "rotation"}
                    if truem[bi, i + 1]:
                        self.add_statistic("obj_mse", smses[bi, i + 1], **tags)
                        self.add_statistic("obj_iou", ious[bi, i + 1], **tags)
        return pred_masks, true_masks
