"""The ClevrTex benchmark's metrics from Python, exact and fast (the Rust `clevrtex eval`).

- `Evaluator`: a drop-in for the public `CLEVRTEX_Evaluator` (same `update` and `statistic`),
  taking numpy arrays or torch tensors (torch is never imported).
- `evaluate(preds, gt, protocol=...)`: every protocol's metrics on arrays, in one call.
- `Dataset`: the published layout (ours or the downloaded ClevrTex) read like the public
  `CLEVRTEX` loader, as numpy arrays; with `as_dict=True` every pass, per-object masks and
  metadata arrays (docs/python.md).
- `collate`: batches `Dataset` items for `torch.utils.data.DataLoader` (torch tensors when
  torch is installed, numpy otherwise).
- `wds.decode`: a sample of the WebDataset shards of `clevrtex export` as arrays (module
  `clevrtex.wds`).

Scoring runs in Rust with the GIL released, in parallel over the images of a batch. Metric
definitions and how the protocols differ: docs/eval.md.
"""

import json
import os
from collections import defaultdict
from typing import Any, Dict, Iterable, List, Optional, Sequence, Tuple, Union

import numpy as np

from . import _native
from . import wds

__all__ = ["Evaluator", "evaluate", "Dataset", "collate", "write_predictions", "PASSES", "METRICS", "protocol_metrics", "wds"]

#: Every metric's name, in report order.
METRICS: Tuple[str, ...] = tuple(_native.metric_names())
_INDEX = {name: i for i, name in enumerate(METRICS)}
# The public evaluator's statistic names that differ from ours.
_PUBLIC_NAMES = {"DICE_FG": "DICE_fg"}
# Per-region statistics `update` adds, tagged by the metadata.
_OBJECT_STATS = ("ground_mse", "ground_iou", "obj_mse", "obj_iou")
MAX_SLOTS = 1024


def protocol_metrics(protocol: str) -> List[str]:
    """The metrics a protocol (`clevrtex`, `native`, `deepmind`, `ocl`) reports by default."""
    return list(_native.protocol_metrics(protocol))


def _numeric(x: np.ndarray, what: str) -> np.ndarray:
    """`x` if its dtype is a number type scores can be read from (bool, integer or float),
    else a ValueError naming the argument and its dtype (object, str, complex, dates, records
    gave bare numpy or pyo3 TypeErrors)."""
    if x.dtype.kind not in "biuf":
        raise ValueError(
            f"`{what}` has dtype `{x.dtype}`: use a bool, integer or float array"
        )
    return x


def _numpy(x: Any, what: str) -> np.ndarray:
    """A numpy view of `x`: numpy arrays as they are, torch tensors through
    `.detach().cpu().numpy()` (without importing torch), anything else through `__array__`."""
    if isinstance(x, np.ndarray):
        return _numeric(x, what)
    for step in ("detach", "cpu"):
        if hasattr(x, step):
            x = getattr(x, step)()
    if hasattr(x, "numpy"):
        return _numeric(np.asarray(x.numpy()), what)
    try:
        return _numeric(np.asarray(x), what)
    except Exception as e:  # pragma: no cover - message only
        raise TypeError(f"`{what}` must be a numpy array or a torch tensor, not {type(x).__name__}") from e


# Dtypes the Rust half reads in place (native byte order, C order); anything else is copied once.
_ID_DTYPES = frozenset(np.dtype(t) for t in (np.uint8, np.uint16, np.uint32, np.uint64, np.int8, np.int16, np.int32, np.int64))
_FLOAT_DTYPES = frozenset(np.dtype(t) for t in (np.float32, np.float64))


def _floats(x: np.ndarray) -> np.ndarray:
    """Soft masks or images for the Rust half: float32/float64 as they are when C-contiguous,
    everything else copied once to float32 (a float64 copy keeps float64: it scores alike)."""
    if x.dtype in _FLOAT_DTYPES:
        return x if x.flags.c_contiguous else np.ascontiguousarray(x)
    return np.ascontiguousarray(x, dtype=np.float32)


def _ids(x: np.ndarray, what: str) -> np.ndarray:
    """Integer (or integral float, or bool) ids for the Rust half, which reads integer arrays in
    place and checks them to be in 0..1024."""
    if np.issubdtype(x.dtype, np.bool_):
        x = x.view(np.uint8)
    elif not np.issubdtype(x.dtype, np.integer):
        if x.size and (not np.all(np.isfinite(x)) or not np.all(np.floor(x) == x)):
            raise ValueError(f"`{what}` must hold integer segment ids")
        if x.size:
            lo, hi = x.min(), x.max()
            if lo < 0 or hi >= MAX_SLOTS:
                bad = lo if lo < 0 else hi
                raise ValueError(f"`{what}` holds segment id `{int(bad)}`, outside 0..{MAX_SLOTS}")
        x = x.astype(np.int64)
    if x.dtype not in _ID_DTYPES or not x.flags.c_contiguous:
        x = np.ascontiguousarray(x, dtype=x.dtype.newbyteorder("="))
    return x


def _check_batch(b: int, h: int, w: int, what: str) -> None:
    """A ValueError unless the batch holds at least one image of at least one pixel (numpy's
    "cannot reshape" otherwise)."""
    if b == 0:
        raise ValueError(f"`{what}` holds no images (B = 0): pass a batch of at least one")
    if h == 0 or w == 0:
        raise ValueError(f"`{what}` images are {h}x{w} pixels: each needs at least one pixel")


def _check_slots(k: int, background: int, what: str) -> None:
    """A ValueError unless `k` masks (plus `background` added) are 1 to MAX_SLOTS slots, the
    limits `clevrtex eval` applies to a prediction file's masks."""
    if k == 0 or k + background > MAX_SLOTS:
        most = MAX_SLOTS - background
        raise ValueError(f"`{what}` has {k} masks: need 1 to {most} (at most {MAX_SLOTS} slots{' with the background added' if background else ''}, as `clevrtex eval` allows)")


def _score(truth, pred, masks, no_background, min_slots, true_rgb=None, pred_rgb=None, pad_to_truth=False, names=("true_masks", "pred")):
    """Score a batch in Rust: `truth` `(B, N)` ids; `pred` `(B, N)` ids (`masks` false) or
    `(B, K, N)` soft masks; images `(B, 3, N)`. The arrays are read in place, not copied."""
    if true_rgb is not None:
        true_rgb, pred_rgb = _floats(true_rgb), _floats(pred_rgb)
        if true_rgb.dtype != pred_rgb.dtype:
            true_rgb, pred_rgb = true_rgb.astype(np.float32), pred_rgb.astype(np.float32)
    return _native.score(
        _ids(truth, names[0]),
        _ids(pred, names[1]) if not masks else _floats(pred),
        no_background,
        min_slots,
        pad_to_truth,
        true_rgb,
        pred_rgb,
        truth_name=names[0],
        pred_name=names[1],
    )


class _RunningMean:
    __slots__ = ("v", "n")

    def __init__(self) -> None:
        self.v = 0.0
        self.n = 0

    def update(self, v: float, n: int = 1) -> None:
        self.v += v * n
        self.n += n

    def value(self) -> float:
        return self.v / self.n if self.n else float("nan")

    def __str__(self) -> str:
        return str(self.value())


def _tag(v: Any) -> Any:
    try:
        hash(v)
        return v
    except TypeError:
        return json.dumps(v)


def _taggable(v: Any, what: str) -> None:
    """A ValueError naming `what` unless `v` can tag a statistic (hashable, or JSON), checked
    before a batch is scored so that a bad value changes no state."""
    try:
        _tag(v)
    except (TypeError, ValueError) as e:
        raise ValueError(f"{what} is a {type(v).__name__}, which cannot tag a statistic: {e}") from None


class Evaluator:
    """Drop-in for the public `CLEVRTEX_Evaluator`: `update(pred_image, pred_masks, true_image,
    true_masks, true_metadata=None)` per batch, then `statistic(name, tag=None)`.

    Statistics: `mIoU`, `mIoU_fg`, `mIoU_gt`, `ARI`, `ARI_FG`, `MSE`, `DICE`, `DICE_FG` (also
    `DICE_fg`), `acc`, `mSC`, `ground_mse`, `ground_iou`, `obj_mse`, `obj_iou` (tagged by the
    metadata), and every other protocol's metric by its name (`mBO`, `dm_FG_ARI`, ...). Values
    undefined for an image (e.g. `mIoU_fg` with nothing but background) are left out of the mean
    where the public code would make the running mean NaN; `mSC` is the correct covering
    (docs/eval.md says how the public loop differs).
    """

    def __init__(self, masks_have_background: bool = True) -> None:
        self.masks_have_background = masks_have_background
        self.stats: Dict[str, _RunningMean] = defaultdict(_RunningMean)
        self.tags: Dict[str, Dict[str, Dict[Any, _RunningMean]]] = defaultdict(
            lambda: defaultdict(lambda: defaultdict(_RunningMean))
        )

    def add_statistic(self, name: str, value: float, **tags: Any) -> None:
        """Add one value (as the public evaluator's `add_statistic` with a scalar)."""
        self.stats[name].update(float(value), 1)
        for k, v in tags.items():
            self.tags[name][k][_tag(v)].update(float(value), 1)

    def statistic(self, name: str, tag: Optional[str] = None) -> Union[float, List[Tuple[Any, float]]]:
        """The running mean of `name` (NaN if nothing was added), or with `tag` the
        `(value, mean)` pairs of that tag sorted by mean, as the public evaluator returns them."""
        name = _PUBLIC_NAMES.get(name, name)
        if name not in self.stats and name not in METRICS and name not in _OBJECT_STATS:
            known = ", ".join(list(METRICS) + list(_OBJECT_STATS) + sorted(set(self.stats) - set(METRICS)))
            raise ValueError(f"unknown statistic `{name}`; known: {known}")
        if tag is None:
            rm = self.stats.get(name)
            return rm.value() if rm is not None else _RunningMean().value()
        by_tag = self.tags.get(name, {}).get(tag, {})
        return sorted(((k, rm.value()) for k, rm in by_tag.items()), key=lambda x: x[1])

    def update(self, pred_image: Any, pred_masks: Any, true_image: Any, true_masks: Any, true_metadata: Optional[Sequence[dict]] = None) -> None:
        """Score a batch: images `(B, 3, H, W)` in [0, 1]; predicted masks `(B, K, 1, H, W)` or
        `(B, K, H, W)` (argmax over K); true masks `(B, 1, H, W)` ids or `(B, K, H, W)` /
        `(B, K, 1, H, W)` one-hot; metadata: one dict per image (`ground_material`, `objects`)."""
        pi = _numpy(pred_image, "pred_image")
        ti = _numpy(true_image, "true_image")
        pm = _numpy(pred_masks, "pred_masks")
        tm = _numpy(true_masks, "true_masks")
        if pi.ndim != 4:
            raise ValueError(f"images should be in (B, C, H, W) shape, `pred_image` is {pi.shape}")
        if ti.shape != pi.shape:
            raise ValueError(f"`true_image` is {ti.shape} but `pred_image` is {pi.shape}")
        b, _, h, w = pi.shape
        _check_batch(b, h, w, "pred_image")
        # Every shape and the metadata checked before anything is scored or counted: a wrong
        # shape is never reshaped into another image's pixels, and an error changes nothing.
        if not 4 <= pm.ndim <= 5 or pm.shape[0] != b or pm.shape[-2:] != (h, w) or (pm.ndim == 5 and pm.shape[2] != 1):
            raise ValueError(
                f"`pred_masks` is {pm.shape}, expected (B, K, 1, H, W) or (B, K, H, W) with (B, H, W) = ({b}, {h}, {w}) from `pred_image` {pi.shape}"
            )
        if not 4 <= tm.ndim <= 5 or tm.shape[0] != b or tm.shape[-2:] != (h, w) or (tm.ndim == 5 and tm.shape[2] != 1):
            raise ValueError(
                f"`true_masks` is {tm.shape}, expected (B, 1, H, W) ids or (B, K, H, W) / (B, K, 1, H, W) one-hot with (B, H, W) = ({b}, {h}, {w}) from `pred_image` {pi.shape}"
            )
        if true_metadata is not None:
            if not hasattr(true_metadata, "__len__") or isinstance(true_metadata, (str, bytes, dict)):
                raise ValueError(f"`true_metadata` is a {type(true_metadata).__name__}, not a list of one dict per image")
            if len(true_metadata) != b:
                raise ValueError(f"`true_metadata` has {len(true_metadata)} entries but the batch has {b} images")
            for i, meta in enumerate(true_metadata):
                if not isinstance(meta, dict):
                    raise ValueError(f"`true_metadata[{i}]` is a {type(meta).__name__}, not a dict")
                if not isinstance(meta.get("objects", []), (list, tuple)):
                    raise ValueError(f"`true_metadata[{i}]['objects']` is a {type(meta['objects']).__name__}, not a list")
                _taggable(meta.get("ground_material"), f"`true_metadata[{i}]['ground_material']`")
                for j, obj in enumerate(meta.get("objects", [])):
                    if not isinstance(obj, dict):
                        raise ValueError(f"`true_metadata[{i}]['objects'][{j}]` is a {type(obj).__name__}, not a dict")
                    for k, v in obj.items():
                        if k != "rotation":
                            _taggable(v, f"`true_metadata[{i}]['objects'][{j}][{k!r}]`")
        _check_slots(pm.shape[1], 0 if self.masks_have_background else 1, "pred_masks")
        if not (tm.ndim == 4 and tm.shape[1] == 1):
            _check_slots(tm.shape[1], 0, "true_masks")
        pm = pm.reshape(b, -1, h * w)
        k_pred = pm.shape[1] + (0 if self.masks_have_background else 1)
        if tm.ndim == 4 and tm.shape[1] == 1:
            # The matching is padded to the batch's largest true id + 1 (found in Rust).
            truth, k_true, pad = tm.reshape(b, h * w), 0, True
        else:
            one_hot = tm.reshape(b, -1, h * w)
            truth, k_true, pad = np.argmax(one_hot, axis=1), one_hot.shape[1], False
        out = _score(
            truth,
            pm,
            True,
            not self.masks_have_background,
            max(k_true, k_pred),
            ti[:, :3].reshape(b, 3, h * w),
            pi[:, :3].reshape(b, 3, h * w),
            pad_to_truth=pad,
        )
        stats = self.stats
        for bi, (values, ious, sizes, sq) in enumerate(out):
            for name, v in zip(METRICS, values):
                if v is not None:
                    rm = stats[name]
                    rm.v += v
                    rm.n += 1
            if true_metadata is not None:
                self._add_tagged(true_metadata[bi], ious, sizes, sq)

    def _add_tagged(self, meta: dict, ious: List[float], sizes: List[int], sq: List[float]) -> None:
        """The per-tag statistics of one image, as `add_statistic` adds them (same order),
        without its per-call overhead (a batch of 64 has about a thousand)."""
        stats, tags = self.stats, self.tags
        ground = meta.get("ground_material")
        added = [("ground_mse", float(sq[0]), (("ground_material", ground),)), ("ground_iou", float(ious[0]), (("ground_material", ground),))]
        for i, obj in enumerate(meta.get("objects", [])):
            if i + 1 < len(sizes) and sizes[i + 1] > 0:
                kv = tuple((k, v) for k, v in obj.items() if k != "rotation")
                added.append(("obj_mse", float(sq[i + 1]), kv))
                added.append(("obj_iou", float(ious[i + 1]), kv))
        for name, value, kv in added:
            rm = stats[name]
            rm.v += value
            rm.n += 1
            by = tags[name]
            for k, v in kv:
                rm = by[k][_tag(v)]
                rm.v += value
                rm.n += 1


def evaluate(
    preds: Any,
    gt: Any,
    protocol: str = "clevrtex",
    metrics: Optional[Iterable[str]] = None,
    no_background: bool = False,
    per_image: bool = False,
) -> Dict[str, Any]:
    """Score predictions against ground truth held in arrays, as `clevrtex eval` scores files.

    `preds`: `(B, H, W)` integer segment ids, or `(B, K, H, W)` soft masks (argmax over K,
    first index on ties; `no_background`: the K masks are foreground only). `gt`: `(B, H, W)`
    true ids (0 = background). Returns `{metric: mean over the images where it is defined, or
    None}` for the protocol's metrics (or `metrics`, any names from `METRICS`, or one name); with `per_image`
    also `"per_image": {metric: [value or None, ...]}`."""
    # One name is one metric, not a list of its characters ("mIoU" -> "m", "I", ...).
    if isinstance(metrics, str):
        metrics = [metrics]
    names = list(metrics) if metrics is not None else protocol_metrics(protocol)
    for n in names:
        if n not in _INDEX:
            raise ValueError(f"unknown metric `{n}`; known: {', '.join(METRICS)}")
    p = _numpy(preds, "preds")
    t = _numpy(gt, "gt")
    if t.ndim != 3:
        raise ValueError(f"`gt` must be (B, H, W) ids, it is {t.shape}")
    b, h, w = t.shape
    _check_batch(b, h, w, "gt")
    if p.ndim == 3:
        if p.shape != t.shape:
            raise ValueError(f"`preds` is {p.shape} but `gt` is {t.shape}")
        out = _score(t.reshape(b, h * w), p.reshape(b, h * w), False, False, 0, names=("gt", "preds"))
    elif p.ndim == 4:
        if (p.shape[0], p.shape[2], p.shape[3]) != (b, h, w):
            raise ValueError(f"`preds` is {p.shape}, expected (B, K, H, W) with (B, H, W) = {t.shape}")
        _check_slots(p.shape[1], 1 if no_background else 0, "preds")
        out = _score(t.reshape(b, h * w), p.reshape(b, p.shape[1], h * w), True, no_background, 0, names=("gt", "preds"))
    else:
        raise ValueError(f"`preds` must be (B, H, W) ids or (B, K, H, W) masks, it is {p.shape}")
    result: Dict[str, Any] = {}
    per: Dict[str, List[Optional[float]]] = {}
    for n in names:
        vals = [o[0][_INDEX[n]] for o in out]
        defined = [v for v in vals if v is not None]
        result[n] = float(np.mean(defined)) if defined else None
        per[n] = vals
    if per_image:
        result["per_image"] = per
    return result


#: Largest metadata file `Dataset` reads (a sample's JSON is a few KB), as the CLI's readers.
MAX_METADATA_BYTES = 64 << 20


def _read_metadata(path: str, root: str) -> bytes:
    """A sample's metadata as the dataset reader reads files (`clevrtex_dataset::dataset`, in
    Rust): a regular file only (a FIFO swapped in never blocks: it is opened non-blocking and
    checked before a byte is read), not a link leading out of the dataset `root`, at most
    `MAX_METADATA_BYTES`; `ValueError` naming the file otherwise, `OSError` (its errno's
    subclass, e.g. `FileNotFoundError`) when it cannot be opened."""
    return _native.read_metadata(path, root)


from ._dataset import PASSES, Dataset, collate  # noqa: E402
from ._predictions import write_predictions  # noqa: E402
