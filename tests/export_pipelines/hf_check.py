"""`hf_check.py OUT SRC`: every shard of `clevrtex export --objects K SRC OUT` (several variants)
loaded at once by Hugging Face `datasets`; each row's record, ids, metres and per-object arrays
equal the dataset's files, through `clevrtex.wds.decode` (uint8 ids, float32 metres, also
as torch tensors). Prints `variants: ... samples: N torch: yes|no`."""
import glob, json, os, sys
import numpy as np
from PIL import Image
import datasets
import clevrtex.wds
out, src = sys.argv[1], sys.argv[2]
index = json.load(open(os.path.join(out, "index.json")))
names, k = index["names"], index["objects"]
urls = sorted(glob.glob(os.path.join(out, "*.tar")))
assert len({os.path.basename(u).split("-")[0] for u in urls}) >= 2, urls
hf = datasets.load_dataset("webdataset", data_files={"train": urls}, split="train")
assert len(hf) == index["samples"], (len(hf), index["samples"])
rows = hf.with_format("numpy")
try:
    import torch
except ImportError:
    torch = None
variants = set()
for i in range(len(hf)):
    rec, arr = hf[i]["json"], rows[i]
    stem = hf[i]["__key__"]
    assert rec["stem"] == stem, (rec["stem"], stem)
    folder = os.path.join(src, "clevrtex_" + rec["variant"], str(rec["index"] // 1000))
    assert rec["metadata"] == open(os.path.join(folder, stem + ".json")).read()
    meta = json.loads(rec["metadata"])
    variants.add(rec["variant"])
    truth = np.array(Image.open(os.path.join(folder, stem + "_flat.png")))
    d = np.array(Image.open(os.path.join(folder, stem + "_depth_0001.png"))).astype(np.float64)
    depth = np.where(d == 65535, np.inf, d * 0.001).astype(np.float32)
    # Hugging Face's own formatters widen ints to int64; the package's decode gives the
    # stored dtypes, from a plain row and from a numpy-formatted one.
    for form in (hf[i], arr):
        a = clevrtex.wds.decode(form)
        assert a["stem"] == stem and a["metadata"] == meta and a["record"]["stem"] == stem
        assert a["mask"].dtype == np.uint8 and np.array_equal(a["mask"], truth), stem
        assert a["depth"].dtype == np.float32 and np.array_equal(a["depth"], depth), stem
        assert a["shape"].dtype == np.int64 and a["bbox"].dtype == np.float32 and a["visibility"].dtype == bool
        if torch is not None:
            tm, td = torch.from_numpy(a["mask"]), torch.from_numpy(a["depth"])
            assert tm.dtype == torch.uint8 and td.dtype == torch.float32
    n = meta["num_objects"]
    assert rec["num_objects"] == n and len(rec["objects"]) == n
    for j, o in enumerate(meta["objects"]):
        r = rec["objects"][j]
        assert r["color"] == (o["color"] or ""), (stem, r["color"])
        for t in ("shape", "size", "material"):
            assert r[t] == o[t] and names[t][arr[t + ".npy"][j]] == o[t], (stem, t)
        c = arr["color.npy"][j]
        assert (c == -1) if o["color"] is None else names["color"][c] == o["color"], (stem, c)
        vis = bool((truth == j + 1).any())
        assert arr["visibility.npy"][j] == vis and arr["valid.npy"][j]
        if vis:
            ys, xs = np.nonzero(truth == j + 1)
            assert arr["bbox.npy"][j].tolist() == [xs.min(), ys.min(), xs.max(), ys.max()], stem
        else:
            assert not arr["bbox.npy"][j].any()
    for t in ("shape", "size", "material", "color"):
        a = arr[t + ".npy"]
        assert a.shape == (k,) and (a[n:] == -1).all(), (stem, t, a)
    assert arr["bbox.npy"].shape == (k, 4) and arr["bbox.npy"].dtype == np.float32
    assert not arr["valid.npy"][n:].any()
print("variants:", " ".join(sorted(variants)), "samples:", len(hf), "torch:", "yes" if torch else "no")
