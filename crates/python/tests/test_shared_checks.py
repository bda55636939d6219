"""Issue 42's hostile pass six, the Python package: what the CLI refuses, the Python readers
refuse too (one validation, shared: the metadata through `check_metadata` of the Rust dataset
reader), `evaluate(metrics="mIoU")` takes one name as one metric, and `clevrtex.wds.decode`
bounds what it decodes."""

import io
import json
import os
import shutil

import numpy as np
import pytest

import clevrtex
from clevrtex import wds

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__)))))
GT = os.path.join(ROOT, "tests", "data", "eval", "gt")


def _copy(tmp_path):
    gt = tmp_path / "gt"
    shutil.copytree(GT, gt)
    f = gt / "clevrtex_vbg" / "0" / "CLEVRTEX_vbg_000001.json"
    return gt, f, json.loads(f.read_text())


@pytest.mark.parametrize(
    "change, key",
    [
        ({"split": "../x"}, "split"),
        ({"split": 5}, "split"),
        ({"num_objects": "4"}, "num_objects"),
        ({"num_objects": 2**63}, "num_objects"),
        ({"num_objects": -1}, "num_objects"),
    ],
)
def test_dataset_refuses_metadata_the_cli_refuses(tmp_path, change, key):
    gt, f, m = _copy(tmp_path)
    f.write_text(json.dumps(dict(m, **change)))
    for as_dict in (False, True):
        ds = clevrtex.Dataset(str(gt), "vbg", split="all", as_dict=as_dict, max_objects=10 if as_dict else None)
        with pytest.raises(ValueError, match=r"CLEVRTEX_vbg_000001.json` key `" + key):
            ds[1]
    # NaN is no JSON value (Python's parser took it).
    f.write_text(json.dumps(m)[:-1] + ', "num_objects": NaN}')
    with pytest.raises(ValueError, match=r"CLEVRTEX_vbg_000001.json` is not valid metadata"):
        clevrtex.Dataset(str(gt), "vbg", split="all")[1]


def test_tuple_form_refuses_a_mask_id_past_the_objects_as_the_dict_form_does(tmp_path):
    from PIL import Image

    gt, f, m = _copy(tmp_path)
    mask = gt / "clevrtex_vbg" / "0" / "CLEVRTEX_vbg_000001_flat.png"
    im = Image.open(mask)
    a = np.array(im)
    a[a.shape[0] // 2 - 2 : a.shape[0] // 2 + 2, a.shape[1] // 2 - 2 : a.shape[1] // 2 + 2] = 200  # kept by the crop
    out = Image.fromarray(a)
    if im.mode == "P":
        out = out.convert("P")
        out.putpalette(im.getpalette())
    out.save(mask)
    for crop in (False, True):
        for as_dict in (False, True):
            ds = clevrtex.Dataset(str(gt), "vbg", split="all", crop=crop, resize=(128, 128) if crop else None, as_dict=as_dict, max_objects=10 if as_dict else None, return_metadata=False)
            with pytest.raises(ValueError, match=r"holds id 200 but the metadata lists 2 objects"):
                ds[1]


def test_evaluate_takes_one_metric_name_as_one_metric():
    rng = np.random.default_rng(4)
    truth = rng.integers(0, 3, size=(2, 8, 8))
    pred = rng.integers(0, 3, size=(2, 8, 8))
    one = clevrtex.evaluate(pred, truth, metrics="mIoU")
    assert set(one) == {"mIoU"}
    assert one == clevrtex.evaluate(pred, truth, metrics=["mIoU"])
    with pytest.raises(ValueError, match=r"unknown metric `miou`"):
        clevrtex.evaluate(pred, truth, metrics="miou")


def _png(w: int, h: int, mode: str = "RGB") -> bytes:
    from PIL import Image

    f = io.BytesIO()
    Image.new(mode, (w, h)).save(f, format="PNG")
    return f.getvalue()


def _npy(a: np.ndarray) -> bytes:
    f = io.BytesIO()
    np.save(f, a)
    return f.getvalue()


def test_wds_decode_bounds_what_it_decodes():
    # 12000x7000 black: 40 KB of PNG, 252 MB of RGB decoded; refused from the header.
    big = _png(12000, 7000, "L")
    with pytest.raises(ValueError, match=r"key `png` declares 12000x7000 pixels, more than the 4096x4096"):
        wds.decode({"__key__": "k", "png": big})
    # JSON nested deeper than Python's parser goes: a ValueError, not a RecursionError.
    with pytest.raises(ValueError, match=r"key `json` is not JSON"):
        wds.decode({"__key__": "k", "json": b"[" * 100000 + b"]" * 100000})
    # A mask of another size than the image belongs to no pixel of it.
    with pytest.raises(ValueError, match=r"passes of different sizes .*`png` 24x32.*`mask.npy` 4096x4096"):
        wds.decode({"__key__": "k", "png": _png(32, 24), "mask.npy": _npy(np.zeros((4096, 4096), np.uint8))})
    s = wds.decode({"__key__": "k", "png": _png(32, 24), "mask.npy": _npy(np.zeros((24, 32), np.uint8))})
    assert s["image"].shape == (24, 32, 3) and s["mask"].shape == (24, 32)
