"""Reading the WebDataset shards of `clevrtex export` as arrays.

A sample of a shard is the files `<stem>.<key>` (the stem is WebDataset's `__key__`):

============  =====================================================================
key           what it holds
============  =====================================================================
`png`         the image: 8-bit sRGB PNG, (H, W, 3)
`mask.npy`    uint8 (H, W) object ids: 0 background, i = `objects[i-1]` of the metadata
`depth.npy`   float32 (H, W) planar depth in metres (along the camera's view axis);
              background +inf
`normal.npy`  float32 (H, W, 3) world-space unit normals; background (0, 0, 0)
`albedo.png`  8-bit PNG, (H, W, 3): the material's base colour
`shadow.npy`  float32 (H, W) shadow amount in [0, 1]; 0 where undefined
`json`        the sample's record, one schema for every variant (stem, variant, split,
              index, objects, camera; `metadata`: the metadata file's text)
============  =====================================================================

With `clevrtex export --objects K`, per-object arrays padded to K: `shape.npy`, `size.npy`,
`material.npy`, `color.npy` (int64 (K,) ids into `ids.json`'s `names`, the dataset's one id table
that `clevrtex.Dataset` uses too; -1 for padding),
`bbox.npy` (float32 (K, 4)), `visibility.npy` and `valid.npy` (bool (K,)).

(A pass the dataset was made without is absent.) Ids, metres, vectors and fractions are NumPy
arrays, never PNGs, so no colour decoder can turn them into colours: `webdataset`'s
`.decode("rgb")` or `.decode("torchrgb")` and Hugging Face's
`datasets.load_dataset("webdataset", data_files=...)` all give the ids and metres as stored.

`decode(sample)` gives one sample with fixed names and types, whichever way it was read
(raw bytes from `webdataset.WebDataset(urls)`, already decoded by `.decode(...)`, or a row
of Hugging Face `datasets`)::

    import webdataset as wds
    import clevrtex.wds

    for s in wds.WebDataset(urls, shardshuffle=False).map(clevrtex.wds.decode):
        s["image"]   # uint8 (H, W, 3)
        s["mask"]    # uint8 (H, W)
        s["depth"]   # float32 (H, W), metres, background +inf

Decoding a PNG from raw bytes needs Pillow; everything else needs only NumPy.
"""

import io
import json
from typing import Any, Dict, Mapping, Optional, Tuple

import numpy as np

__all__ = ["KEYS", "MAX_SIDE", "OBJECT_KEYS", "decode"]

#: The largest side of an image `decode` decodes from PNG bytes: clevrtex's own cap on an
#: image's side (`MAX_IMAGE_SIDE`). A few hundred bytes of PNG can declare 12000x7000 pixels
#: (833 MB decoded); the header is read first and such a PNG refused before any pixel.
MAX_SIDE = 4096

#: The keys of a sample in a shard -> the name `decode` gives them, the dtype and the
#: number of channels of the array (`None`: not an array).
KEYS: Dict[str, Tuple[str, Optional[str], Optional[int]]] = {
    "png": ("image", "uint8", 3),
    "mask.npy": ("mask", "uint8", 1),
    "depth.npy": ("depth", "float32", 1),
    "normal.npy": ("normal", "float32", 3),
    "albedo.png": ("albedo", "uint8", 3),
    "shadow.npy": ("shadow", "float32", 1),
    "json": ("metadata", None, None),
}

#: The per-object keys of `clevrtex export --objects K` -> the name `decode` gives them, the
#: dtype and the number of dimensions of the array.
OBJECT_KEYS: Dict[str, Tuple[str, str, int]] = {
    f"{name}.npy": (name, dtype, ndim)
    for name, dtype, ndim in [
        ("shape", "int64", 1),
        ("size", "int64", 1),
        ("material", "int64", 1),
        ("color", "int64", 1),
        ("bbox", "float32", 2),
        ("visibility", "bool", 1),
        ("valid", "bool", 1),
    ]
}


def _object_array(key: str, stem: Any, value: Any) -> np.ndarray:
    name, dtype, ndim = OBJECT_KEYS[key]
    where = f"sample `{stem}` key `{key}`"
    if isinstance(value, (bytes, bytearray, memoryview)):
        try:
            value = np.lib.format.read_array(io.BytesIO(bytes(value)), allow_pickle=False)
        except Exception as e:  # numpy raises ValueError or OSError for a bad file
            raise ValueError(f"{where} is not a .npy array: {e}") from None
    for step in ("detach", "cpu", "numpy"):
        if hasattr(value, step):
            value = getattr(value, step)()
    arr = np.asarray(value)
    if arr.ndim != ndim or (ndim == 2 and arr.shape[-1] != 4) or arr.dtype.kind not in "biuf":
        raise ValueError(f"{where} is a {arr.dtype} array of shape {arr.shape}, not {dtype} {name}")
    return np.ascontiguousarray(arr, dtype=dtype)


def _array(key: str, stem: Any, value: Any) -> np.ndarray:
    """The array of `value` (bytes of a `.npy` or PNG, an array or tensor a decoder made,
    nested lists from Hugging Face, a PIL image) in the dtype and layout of `KEYS[key]`."""
    name, dtype, channels = KEYS[key]
    where = f"sample `{stem}` key `{key}`"
    if isinstance(value, (bytes, bytearray, memoryview)):
        data = bytes(value)
        if key.endswith(".npy"):
            try:
                arr = np.lib.format.read_array(io.BytesIO(data), allow_pickle=False)
            except Exception as e:  # numpy raises ValueError or OSError for a bad file
                raise ValueError(f"{where} is not a .npy array: {e}") from None
        else:
            try:
                from PIL import Image
            except ImportError:
                raise ImportError(
                    f"{where}: decoding a PNG from bytes needs Pillow (`pip install pillow`), "
                    "or read the shards with `.decode(\"rgb\")`"
                ) from None
            try:
                im = Image.open(io.BytesIO(data))
                size = im.size
            except Exception as e:
                raise ValueError(f"{where} is not a PNG: {e}") from None
            if max(size) > MAX_SIDE:
                raise ValueError(
                    f"{where} declares {size[0]}x{size[1]} pixels, more than the "
                    f"{MAX_SIDE}x{MAX_SIDE} any clevrtex image has; not decoded"
                )
            try:
                arr = np.asarray(im.convert("RGB"))
            except Exception as e:
                raise ValueError(f"{where} is not a PNG: {e}") from None
    else:
        tensor = hasattr(value, "detach")  # a torch tensor, without importing torch
        for step in ("detach", "cpu", "numpy"):
            if hasattr(value, step):
                value = getattr(value, step)()
        arr = np.asarray(value)
        # A colour decoder's image: float in [0, 1] (`rgb`), a channels-first tensor
        # (`torchrgb`).
        if key.endswith("png"):
            if arr.ndim == 3 and arr.shape[0] == 3 and (tensor or arr.shape[-1] != 3):
                arr = arr.transpose(1, 2, 0)
            if arr.dtype.kind == "f":
                arr = np.clip(np.round(arr * 255.0), 0, 255).astype(np.uint8)
    want_ndim = 2 if channels == 1 else 3
    if arr.ndim != want_ndim or (channels == 3 and arr.shape[-1] != 3):
        shape = "(H, W)" if channels == 1 else "(H, W, 3)"
        raise ValueError(f"{where} has shape {arr.shape}, not {shape}")
    if key.endswith(".npy") and arr.dtype.kind not in ("biu" if dtype == "uint8" else "biuf"):
        raise ValueError(f"{where} has dtype {arr.dtype}, not {dtype}")
    if dtype == "uint8" and arr.dtype != np.uint8 and arr.size and (arr.min() < 0 or arr.max() > 255):
        raise ValueError(f"{where} holds values outside 0..255, not uint8 {name}")
    return np.ascontiguousarray(arr, dtype=dtype)


def decode(sample: Mapping[str, Any]) -> Dict[str, Any]:
    """One sample of a `clevrtex export` shard as arrays: `key` and `stem` (the stem), `image` uint8
    (H, W, 3), `mask` uint8 (H, W) ids, `depth` float32 (H, W) metres (+inf background),
    `normal` float32 (H, W, 3), `albedo` uint8 (H, W, 3), `shadow` float32 (H, W) and
    `metadata` (the metadata file, a dict; `record`: the shard's `json` record), and the
    per-object arrays of `--objects K` (`shape`, `size`, `material`, `color` int64, `bbox`
    float32, `visibility`, `valid` bool); what the sample lacks is absent. `sample` is a dict as
    `webdataset` yields it (raw or after `.decode("rgb")`, `"torchrgb"`, ...) or a row of a
    Hugging Face `datasets` table. A value that is not what its key holds is a ValueError
    naming the sample and the key."""
    if not isinstance(sample, Mapping):
        raise TypeError(f"a sample is a dict of its keys, not {type(sample).__name__}")
    stem = sample.get("__key__")
    out: Dict[str, Any] = {"key": stem, "stem": stem}
    for key, (name, _, _) in KEYS.items():
        if key not in sample or sample[key] is None:
            continue
        value = sample[key]
        if key == "json":
            if isinstance(value, (bytes, bytearray, memoryview, str)):
                try:
                    value = json.loads(bytes(value) if not isinstance(value, str) else value)
                except (UnicodeDecodeError, json.JSONDecodeError, RecursionError) as e:
                    # RecursionError: nested deeper than Python's parser goes.
                    raise ValueError(f"sample `{stem}` key `json` is not JSON: {e or 'nested too deep'}") from None
            if not isinstance(value, dict):
                raise ValueError(
                    f"sample `{stem}` key `json` is a {type(value).__name__}, not an object"
                )
            # The record (one schema for every variant) holds the metadata file's text; the
            # shards of earlier exports held the metadata itself.
            if isinstance(value.get("metadata"), str):
                out["record"] = value
                try:
                    value = json.loads(value["metadata"])
                except (json.JSONDecodeError, RecursionError) as e:
                    raise ValueError(f"sample `{stem}` key `json` holds `metadata` that is not JSON: {e or 'nested too deep'}") from None
                if not isinstance(value, dict):
                    raise ValueError(f"sample `{stem}` key `json` holds `metadata` that is not an object")
            out[name] = value
        else:
            out[name] = _array(key, stem, value)
    # Every pass is one image's: a mask or depth of another size than the image belongs to
    # no pixel of it.
    sizes = {
        key: out[name].shape[:2] for key, (name, dtype, _) in KEYS.items() if dtype and name in out
    }
    if len(set(sizes.values())) > 1:
        shown = ", ".join(f"`{k}` {h}x{w}" for k, (h, w) in sizes.items())
        raise ValueError(f"sample `{stem}` has passes of different sizes ({shown}, as height x width): every pass is the image's size")
    for key, (name, _, _) in OBJECT_KEYS.items():
        if sample.get(key) is not None:
            out[name] = _object_array(key, stem, sample[key])
    return out
