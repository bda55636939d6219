"""`clevrtex.Dataset` and `clevrtex.collate`: a dataset in the published layout, read through
the Rust dataset reader (`clevrtex_dataset::dataset`: no link out of the dataset followed, no
FIFO opened, capped reads), as numpy arrays, ready for `torch.utils.data.DataLoader`.

A `Dataset` holds only strings, numbers and lists (no open file, no native handle), so it
pickles into DataLoader workers under fork and spawn alike. The keys, shapes, dtypes and units
of an item are documented in docs/python.md.
"""

import importlib
import json
import os
from typing import Any, Dict, List, Optional, Sequence, Tuple

import numpy as np

from . import _native

#: The optional passes `Dataset(..., passes=...)` can add, with their channels.
PASSES = {"depth": 1, "normal": 3, "albedo": 3, "shadow": 1}
_SPLITS = ("test", "val", "train")


def _read_json(path: str, root: str) -> dict:
    """A sample's metadata, read by the Rust dataset reader (never Python's `open`)."""
    try:
        data = json.loads(_native.read_metadata(path, root))
    except (UnicodeDecodeError, json.JSONDecodeError, RecursionError) as e:
        raise ValueError(f"`{path}` is not valid metadata: {e}") from None
    if not isinstance(data, dict):
        raise ValueError(f"`{path}` is not valid metadata: a {type(data).__name__}, not an object")
    return data


def _field(meta: dict, path: str, *keys: Any) -> Any:
    """`meta[k0][k1]...`, or a ValueError naming the file and the key that is missing."""
    v: Any = meta
    for i, k in enumerate(keys):
        try:
            v = v[k]
        except (KeyError, IndexError, TypeError):
            where = "".join(f"[{x!r}]" for x in keys[: i + 1])
            raise ValueError(f"`{path}` has no key {where}, which the Dataset needs for its arrays") from None
    if v is None:
        where = "".join(f"[{x!r}]" for x in keys)
        raise ValueError(f"`{path}` key {where} is null, which the Dataset needs for its arrays")
    return v


def _floats(v: Any, shape: Tuple[int, ...], path: str, key: str) -> np.ndarray:
    try:
        a = np.asarray(v, dtype=np.float64)
    except (TypeError, ValueError):
        a = None
    if a is None or a.shape != shape or not np.all(np.isfinite(a)):
        raise ValueError(f"`{path}` key `{key}` is not {' x '.join(map(str, shape)) or 'a'} finite number(s)")
    return a


def _check_mask_ids(mask: np.ndarray, n: int, path: str) -> None:
    """A ValueError when the mask holds an id past the `n` objects of the metadata `path`."""
    if mask.size and int(mask.max()) > n:
        raise ValueError(f"the mask of `{path}` holds id {int(mask.max())} but the metadata lists {n} objects")


class Dataset:
    """A ClevrTex dataset in the published layout (made by `clevrtex generate` or downloaded).

    By default read like the public `CLEVRTEX` loader: `ds[i]` is `(index, image, mask)` or,
    with `return_metadata`, `(index, image, mask, metadata)`; `image` is `(3, H, W)` float32 in
    [0, 1], `mask` `(1, H, W)` ids (uint8 when they fit). The crop (centre square of side
    `int(0.8 min(W, H))`) and the resize (Pillow-exact bilinear, nearest for the mask) equal the
    public loader's bit for bit.

    With `as_dict=True`, `ds[i]` is a dict of arrays a model can use (docs/python.md): the
    image and mask, the optional `passes` (`depth`, `normal`, `albedo`, `shadow`), per-object
    masks padded to `max_objects` with a visibility vector, every object's properties as ids
    and numbers, and the camera. Batch it with `DataLoader(ds, batch_size=B,
    collate_fn=clevrtex.collate)`. No torch needed.

    The split is each sample's, as the dataset reader gives it; an empty split is a ValueError
    naming the split sizes found.
    """

    ccrop_frac = 0.8
    splits = {"test": (0.0, 0.1), "val": (0.1, 0.2), "train": (0.2, 1.0)}

    def __init__(
        self,
        path: str,
        dataset_variant: Optional[str] = "full",
        split: str = "train",
        crop: bool = True,
        resize: Optional[Tuple[int, int]] = (128, 128),
        return_metadata: bool = True,
        as_dict: bool = False,
        passes: Sequence[str] = (),
        max_objects: Optional[int] = None,
        names: Optional[Dict[str, Sequence[str]]] = None,
    ) -> None:
        if split not in self.splits and split != "all":
            raise ValueError(f"unknown split `{split}`; known: test, val, train, all")
        if resize is not None and (len(resize) != 2 or resize[0] != resize[1]):
            raise ValueError(f"`resize` must be square (the benchmark's is (128, 128)), not {resize}")
        if resize is not None and not 1 <= int(resize[0]) <= 4096:
            raise ValueError(f"`resize` must be 1 to 4096 a side (the benchmark's is (128, 128)), not {resize}")
        if isinstance(passes, str):
            passes = (passes,)
        passes = tuple(passes)
        for p in passes:
            if p not in PASSES:
                raise ValueError(f"unknown pass `{p}` in `passes`; known: {', '.join(PASSES)}")
        if not as_dict and (passes or max_objects is not None):
            raise ValueError("`passes` and `max_objects` need `as_dict=True` (the tuple form is the public loader's)")
        if max_objects is not None and (isinstance(max_objects, bool) or not isinstance(max_objects, (int, np.integer)) or max_objects <= 0):
            raise ValueError(f"`max_objects` must be a whole number of at least 1, not {max_objects!r}")
        self.crop = crop
        self.side = None if resize is None else int(resize[0])
        self.return_metadata = return_metadata
        self.as_dict = as_dict
        self.passes = passes
        self._root = str(path)
        self.dataset_variant, self._samples = _native.discover(self._root, dataset_variant, split)
        self.split = split
        if not self._samples:
            sizes = {s: len(_native.discover(self._root, dataset_variant, s)[1]) for s in _SPLITS}
            found = ", ".join(f"{s} {n}" for s, n in sizes.items())
            raise ValueError(f"split `{split}` of `{self.dataset_variant}` in `{self._root}` is empty (splits found: {found}); pick another `split` or `split=\"all\"`")
        # Objects carry their colour where the variant's config gives them one (vbg, clevr).
        self._by_colour = _native.colour_breakdown(self.dataset_variant)
        self._suffix = {name: suffix for name, suffix, _ in _native.pass_files()}
        self._pass_key = {name: key for name, _, key in _native.pass_files()}
        # The dataset's one id table (the WebDataset and COCO exports' `ids.json`), whatever
        # the variant; the sizes' scales are the variant's own.
        shapes, sizes, materials, colors = _native.id_tables(self._root)
        tables: Dict[str, List[str]] = {"shape": list(shapes), "size": list(sizes), "material": list(materials), "color": list(colors)}
        known = _native.variant_names(self.dataset_variant, self._root)
        self.scales: Dict[str, float] = {n: float(s) for n, s in known[1]} if known is not None else {}
        for k, v in (names or {}).items():
            if k not in tables:
                raise ValueError(f"unknown name table `{k}` in `names`; known: {', '.join(tables)}")
            tables[k] = [str(x) for x in v]
        #: The name tables the id arrays index: `names["shape"][shape_id]` etc.
        self.names: Dict[str, List[str]] = tables
        self._ids = {k: {n: i for i, n in enumerate(v)} for k, v in tables.items()}
        self.max_objects = max_objects
        if as_dict:
            # The first sample says at once what the dataset lacks (a pass, a field).
            first = _read_json(self._samples[0][3], self._root)
            for p in passes:
                if first.get(self._pass_key[p]) is None:
                    have = [n for n in ("rgb", "mask", *PASSES) if first.get(self._pass_key[n]) is not None]
                    raise ValueError(f"the dataset has no `{p}` pass (`{self._samples[0][3]}` lists {', '.join(have) or 'none'}); leave it out of `passes` or generate with `--passes` including it")
            if max_objects is None:
                raise ValueError("`as_dict=True` needs `max_objects`: the K the per-object arrays are padded to (e.g. 10, ClevrTex's most objects)")

    def __len__(self) -> int:
        return len(self._samples)

    def stem(self, ind: int) -> str:
        """The stem of item `ind` (`CLEVRTEX_<variant>_<index:06d>`): the name its predictions
        take for `clevrtex eval` (`clevrtex.write_predictions`)."""
        return os.path.basename(self._samples[ind][1])[: -len(".png")]

    def _format_metadata(self, meta: dict, path: str, stem: str) -> dict:
        objects = meta.get("objects", [])
        if not isinstance(objects, list):
            raise ValueError(f"`{path}` key `objects` is a {type(objects).__name__}, not a list")
        objs = []
        for i, obj in enumerate(objects):
            if not isinstance(obj, dict):
                raise ValueError(f"`{path}` key `objects[{i}]` is a {type(obj).__name__}, not an object")
            o = {k: obj.get(k) for k in ("material", "shape", "size", "rotation")}
            if self._by_colour:
                o["color"] = obj.get("color")
            objs.append(o)
        return {"ground_material": meta.get("ground_material"), "objects": objs, "stem": stem}

    def _id(self, table: str, name: Any, path: str, key: str) -> int:
        ids = self._ids[table]
        if name not in ids:
            shown = ", ".join(self.names[table]) or "empty"
            raise ValueError(f"`{path}` key `{key}` is {name!r}, not in the `{table}` name table ({shown}); pass `names={{'{table}': [...]}}`")
        return ids[name]

    def __getitem__(self, ind: int):
        n = len(self._samples)
        if not isinstance(ind, (int, np.integer)):
            raise TypeError(f"a Dataset is indexed by an int, not {type(ind).__name__}")
        if ind < -n or ind >= n:
            raise IndexError(f"index {ind} is out of range for a Dataset of {n} samples")
        index, image, mask, meta = self._samples[ind]
        stem_path = image[: -len(".png")]
        stem = os.path.basename(stem_path)
        wanted = [(p, stem_path + self._suffix[p] + ".png") for p in self.passes]
        rgb, labels, h, w, size, decoded = _native.load_item(image, mask, wanted, self.crop, self.side, self._root)
        img = np.frombuffer(rgb, dtype=np.uint8).reshape(h, w, 3).transpose(2, 0, 1).astype(np.float32) / np.float32(255)
        msk = np.frombuffer(labels, dtype="<u4").reshape(1, h, w)
        msk = msk.astype(np.uint8) if (msk.size == 0 or msk.max() < 256) else msk.astype(np.int64)
        # Read (and checked as the CLI checks it) for every item: the tuple form refuses a
        # mask id past the metadata's objects as the dict form does.
        data = _read_json(meta, self._root)
        if not self.as_dict:
            objects = data.get("objects", [])
            _check_mask_ids(msk[0], len(objects) if isinstance(objects, list) else 0, meta)
            if not self.return_metadata:
                return index, img, msk
            return index, img, msk, self._format_metadata(data, meta, stem)
        item: Dict[str, Any] = {"index": np.int64(index), "stem": stem, "image": img, "mask": msk}
        for name, buf, c in decoded:
            item[name] = np.frombuffer(buf, dtype=np.float32).reshape(c, h, w).copy()
        item.update(self._arrays(data, meta, msk[0], (h, w), size))
        if self.return_metadata:
            item["metadata"] = self._format_metadata(data, meta, stem)
        return item

    def _arrays(self, meta: dict, path: str, mask: np.ndarray, out_hw: Tuple[int, int], file_wh: Tuple[int, int]) -> Dict[str, np.ndarray]:
        """The per-object arrays (padded to K) and the camera of one sample (`file_wh`: the image
        file's width and height, which the metadata's `render` size must equal)."""
        k = int(self.max_objects or 0)
        objects = _field(meta, path, "objects")
        if not isinstance(objects, list):
            raise ValueError(f"`{path}` key `objects` is a {type(objects).__name__}, not a list")
        n = len(objects)
        if n > k:
            raise ValueError(f"`{path}` has {n} objects, more than `max_objects` = {k}: pass a larger `max_objects`")
        _check_mask_ids(mask, n, path)
        shape = np.full(k, -1, np.int64)
        size = np.full(k, -1, np.int64)
        material = np.full(k, -1, np.int64)
        color = np.full(k, -1, np.int64)
        scale = np.zeros(k, np.float32)
        rotation = np.zeros(k, np.float32)
        coords = np.zeros((k, 3), np.float32)
        pixel = np.zeros((k, 3), np.float32)
        visible_px = np.zeros(k, np.int64)
        for i, o in enumerate(objects):
            key = f"objects[{i}]"
            if not isinstance(o, dict):
                raise ValueError(f"`{path}` key `{key}` is a {type(o).__name__}, not an object")
            shape[i] = self._id("shape", _field(o, path, "shape"), path, key + ".shape")
            sname = _field(o, path, "size")
            size[i] = self._id("size", sname, path, key + ".size")
            scale[i] = self.scales.get(sname, np.nan)
            material[i] = self._id("material", _field(o, path, "material"), path, key + ".material")
            if self._by_colour:
                color[i] = self._id("color", _field(o, path, "color"), path, key + ".color")
            rotation[i] = _floats(_field(o, path, "rotation"), (), path, key + ".rotation")
            coords[i] = _floats(_field(o, path, "3d_coords"), (3,), path, key + ".3d_coords")
            pixel[i] = _floats(_field(o, path, "pixel_coords"), (3,), path, key + ".pixel_coords")
            vp = _field(o, path, "visible_pixels")
            if isinstance(vp, bool) or not isinstance(vp, int) or vp < 0:
                raise ValueError(f"`{path}` key `{key}.visible_pixels` is {vp!r}, not a whole number")
            visible_px[i] = vp
        intr = _floats(_field(meta, path, "camera", "intrinsics"), (3, 3), path, "camera.intrinsics")
        extr = _floats(_field(meta, path, "camera", "extrinsics"), (4, 4), path, "camera.extrinsics")
        width = _field(meta, path, "render", "width")
        height = _field(meta, path, "render", "height")
        if isinstance(width, bool) or isinstance(height, bool) or (width, height) != tuple(file_wh):
            raise ValueError(f"`{path}` key `render` gives a {width!r} x {height!r} image, but the image file is {file_wh[0]} x {file_wh[1]}")
        # The pixel frame of the returned image: the crop's offset, then its scale.
        if self.crop:
            c = int(0.8 * min(width, height))
            x0, y0 = (width - c) // 2, (height - c) // 2
            s = out_hw[0] / c
        else:
            x0, y0, s = 0, 0, 1.0
        to_out = np.array([[s, 0, -x0 * s], [0, s, -y0 * s], [0, 0, 1]], np.float64)
        pixel[:n, 0] = (pixel[:n, 0] - x0) * s
        pixel[:n, 1] = (pixel[:n, 1] - y0) * s
        ids = np.arange(1, k + 1, dtype=mask.dtype if mask.dtype != np.uint8 or k < 256 else np.int64)
        object_masks = mask[None, :, :] == ids[:, None, None]
        visibility = object_masks.any(axis=(1, 2))
        bbox = np.zeros((k, 4), np.float32)
        rows = object_masks.any(axis=2)
        cols = object_masks.any(axis=1)
        for i in np.flatnonzero(visibility):
            ys, xs = np.flatnonzero(rows[i]), np.flatnonzero(cols[i])
            bbox[i] = (xs[0], ys[0], xs[-1], ys[-1])
        ground = meta.get("ground_material")
        return {
            "num_objects": np.int64(n),
            "valid": np.arange(k) < n,
            "visibility": visibility,
            "object_masks": object_masks,
            "bbox": bbox,
            "shape": shape,
            "size": size,
            "scale": scale,
            "material": material,
            "color": color,
            "rotation": rotation,
            "coords_3d": coords,
            "pixel_coords": pixel,
            "visible_pixels": visible_px,
            "ground_material": np.int64(self._id("material", ground, path, "ground_material") if ground is not None else -1),
            "intrinsics": (to_out @ intr).astype(np.float32),
            "extrinsics": extr.astype(np.float32),
        }


_torch: Any = None


def _torch_module() -> Any:
    """torch when it is installed (imported on first use), else False."""
    global _torch
    if _torch is None:
        try:
            _torch = importlib.import_module("torch")
        except ImportError:
            _torch = False
    return _torch


def collate(batch: Sequence[Any], tensors: Optional[bool] = None) -> Any:
    """Batch `Dataset` items for `DataLoader(ds, batch_size=B, collate_fn=clevrtex.collate)`.

    Arrays of one shape are stacked on a new first axis (numbers become `(B,)` arrays); dicts
    and tuples are batched key by key; the metadata dicts and strings (the stems) stay a list
    of one per item, as `Evaluator.update` takes them. With torch installed (or `tensors=True`) the arrays
    are torch tensors (bool, uint8, int64, float32 kept), else numpy (`tensors=False`: always).
    """
    if tensors is None:
        tensors = bool(_torch_module())
    elif tensors and not _torch_module():
        raise ValueError("`tensors=True` needs torch, which is not installed")
    return _collate(list(batch), tensors)


def _collate(batch: List[Any], tensors: bool) -> Any:
    if not batch:
        raise ValueError("`collate` got an empty batch")
    first = batch[0]
    if isinstance(first, dict) and not any(isinstance(v, list) for v in first.values()) and "objects" not in first:
        return {k: _collate([b[k] for b in batch], tensors) for k in first}
    if isinstance(first, tuple):
        if any(len(b) != len(first) for b in batch):
            raise ValueError("`collate` got items of different lengths")
        return tuple(_collate(list(x), tensors) for x in zip(*batch))
    if isinstance(first, (np.ndarray, np.generic, int, float)) and not isinstance(first, (bool, str)):
        arrays = [np.asarray(b) for b in batch]
        if any(a.shape != arrays[0].shape for a in arrays):
            shapes = sorted({a.shape for a in arrays})
            raise ValueError(f"`collate` cannot stack arrays of shapes {shapes}: use a fixed `resize` and `max_objects`")
        out = np.stack(arrays)
        return _torch.from_numpy(out) if tensors else out
    if hasattr(first, "shape") and hasattr(first, "dim") and tensors:  # torch tensors
        return _torch.stack(list(batch))
    return list(batch)
