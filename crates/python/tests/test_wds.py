"""`clevrtex.wds.decode`: a sample of `clevrtex export`'s shards as arrays, from every form a
reader gives it (raw bytes, a decoder's arrays, Hugging Face's lists); values that are not what
their key holds are a ValueError naming the sample and the key. (Real shards read with the real
`webdataset` and `datasets` libraries: tests/export.rs.)"""

import io
import json

import numpy as np
import pytest

import clevrtex
from clevrtex import wds


def npy(a: np.ndarray) -> bytes:
    f = io.BytesIO()
    np.save(f, a)
    return f.getvalue()


MASK = np.array([[0, 1], [2, 2]], dtype=np.uint8)
DEPTH = np.array([[np.inf, 1.5], [2.25, 3.0]], dtype=np.float32)


def test_decode_gives_one_form_from_every_reader():
    meta = {"stem": "CLEVRTEX_clevr_000000", "num_objects": 2}
    raw = {"__key__": "CLEVRTEX_clevr_000000", "mask.npy": npy(MASK), "depth.npy": npy(DEPTH), "json": json.dumps(meta).encode()}
    decoded = {"__key__": "CLEVRTEX_clevr_000000", "mask.npy": MASK, "depth.npy": DEPTH, "json": meta}
    hf = {"__key__": "CLEVRTEX_clevr_000000", "mask.npy": MASK.tolist(), "depth.npy": DEPTH.tolist(), "json": meta}
    for form in (raw, decoded, hf):
        s = wds.decode(form)
        assert s["key"] == "CLEVRTEX_clevr_000000" and s["metadata"] == meta
        assert s["mask"].dtype == np.uint8 and np.array_equal(s["mask"], MASK)
        assert s["depth"].dtype == np.float32 and np.array_equal(s["depth"], DEPTH)
        assert "normal" not in s and "image" not in s
    assert clevrtex.wds is wds and "wds" in clevrtex.__all__


def test_decode_turns_a_colour_decoder_s_image_back_into_bytes():
    class Tensor:
        """What `decode` uses of a torch tensor (torch itself may be absent)."""

        def __init__(self, a):
            self.a = a

        def detach(self):
            return self

        def cpu(self):
            return self

        def numpy(self):
            return self.a

    for h, w in ((4, 5), (2, 3)):
        image = np.arange(h * w * 3, dtype=np.uint8).reshape(h, w, 3)
        as_rgb = image.astype(np.float32) / 255  # `.decode("rgb")`
        as_torchrgb = Tensor(as_rgb.transpose(2, 0, 1))  # `.decode("torchrgb")`: (3, H, W)
        for value in (as_rgb, as_torchrgb):
            assert np.array_equal(wds.decode({"__key__": "k", "png": value})["image"], image)


@pytest.mark.parametrize(
    "sample, message",
    [
        ({"mask.npy": b"not an array"}, "key `mask.npy` is not a .npy array"),
        ({"mask.npy": npy(np.zeros((2, 2, 2), np.uint8))}, "key `mask.npy` has shape (2, 2, 2), not (H, W)"),
        ({"mask.npy": [[256]]}, "key `mask.npy` holds values outside 0..255"),
        ({"mask.npy": npy(np.zeros((2, 2), np.float32))}, "key `mask.npy` has dtype float32, not uint8"),
        ({"normal.npy": npy(np.zeros((2, 2), np.float32))}, "key `normal.npy` has shape (2, 2), not (H, W, 3)"),
        ({"json": b"[1, 2]"}, "key `json` is a list, not an object"),
        ({"json": b"{"}, "key `json` is not JSON"),
    ],
)
def test_decode_names_the_sample_and_key_of_what_is_wrong(sample, message):
    with pytest.raises(ValueError, match="sample `S` " + message.replace("(", r"\(").replace(")", r"\)").replace(".", r"\.")):
        wds.decode({"__key__": "S", **sample})
    with pytest.raises(TypeError):
        wds.decode([1, 2])


def test_decode_reads_the_record_and_the_per_object_arrays():
    # Issue 43: the shard's `json` is a record of one schema holding the metadata file's text;
    # `--objects K` adds per-object arrays. HF widens ints to int64: decode gives the dtypes back.
    meta = {"stem": "CLEVRTEX_camo_000004", "num_objects": 1, "objects": [{"color": None}]}
    record = {"stem": meta["stem"], "objects": [{"color": ""}], "metadata": json.dumps(meta)}
    shape = np.array([2, -1, -1], np.int64)
    bbox = np.array([[0, 1, 1, 1], [0, 0, 0, 0], [0, 0, 0, 0]], np.float32)
    vis = np.array([True, False, False])
    raw = {"__key__": meta["stem"], "json": json.dumps(record).encode(), "mask.npy": npy(MASK),
           "shape.npy": npy(shape), "bbox.npy": npy(bbox), "visibility.npy": npy(vis)}
    hf = {"__key__": meta["stem"], "json": record, "mask.npy": MASK.astype(np.int64),
          "shape.npy": shape.tolist(), "bbox.npy": bbox.tolist(), "visibility.npy": vis.tolist()}
    for form in (raw, hf):
        s = wds.decode(form)
        assert s["stem"] == s["key"] == meta["stem"] and s["metadata"] == meta and s["record"] == record
        assert s["mask"].dtype == np.uint8 and np.array_equal(s["mask"], MASK)
        assert s["shape"].dtype == np.int64 and np.array_equal(s["shape"], shape)
        assert s["bbox"].dtype == np.float32 and np.array_equal(s["bbox"], bbox)
        assert s["visibility"].dtype == bool and np.array_equal(s["visibility"], vis)
        assert "color" not in s
    with pytest.raises(ValueError, match="key `bbox.npy` is a float32 array of shape \\(3,\\)"):
        wds.decode(dict(raw, **{"bbox.npy": npy(np.zeros(3, np.float32))}))
    with pytest.raises(ValueError, match="holds `metadata` that is not JSON"):
        wds.decode(dict(raw, json=json.dumps(dict(record, metadata="{nope")).encode()))
