"""`crop_check.py OUT SRC SIDE K`: shards of `clevrtex export --crop --resize SIDE --objects K SRC OUT`
equal the Python `Dataset`'s items with `crop=True, resize=(SIDE, SIDE)` (the public loader's crop
and resize, bit for bit): image, mask, depth, per-object boxes and visibility, intrinsics and
pixel coordinates. Prints `samples: N`."""
import glob, json, os, sys
import numpy as np
import webdataset as wds
import clevrtex
out, src, side, k = sys.argv[1], sys.argv[2], int(sys.argv[3]), int(sys.argv[4])
n = 0
for url in sorted(glob.glob(os.path.join(out, "*.tar"))):
    variant = os.path.basename(url).split("-")[0]
    ds = clevrtex.Dataset(src, variant, split="all", crop=True, resize=(side, side), as_dict=True, passes=("depth",), max_objects=k)
    by_stem = {ds.stem(i): i for i in range(len(ds))}
    for s in wds.WebDataset(url, shardshuffle=False).map(clevrtex.wds.decode):
        item = ds[by_stem[s["stem"]]]
        assert s["image"].shape == (side, side, 3), s["image"].shape
        assert np.array_equal(s["image"], np.round(item["image"] * 255).astype(np.uint8).transpose(1, 2, 0)), s["stem"]
        assert np.array_equal(s["mask"], item["mask"][0]), s["stem"]
        assert np.array_equal(s["depth"], item["depth"][0]), s["stem"]
        assert np.array_equal(s["visibility"], item["visibility"]) and np.array_equal(s["bbox"], item["bbox"]), s["stem"]
        assert np.array_equal(s["valid"], item["valid"]), s["stem"]
        for key in ("shape", "size", "material", "color"):  # the dataset's one id table
            assert np.array_equal(s[key], item[key]), (s["stem"], key, s[key], item[key])
        rec = s["record"]
        assert np.allclose(np.array(rec["intrinsics"], np.float32), item["intrinsics"], atol=1e-5), s["stem"]
        got = np.array([o["pixel_coords"] for o in rec["objects"]], np.float32)
        assert np.allclose(got, item["pixel_coords"][: len(got)], atol=1e-4), s["stem"]
        n += 1
print("samples:", n)
