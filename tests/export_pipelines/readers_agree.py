"""`readers_agree.py SRC WDS CROP RESIZED SIDE COCO K`: one dataset of several variants read by
every reader gives the same numbers (issue 49). The Python `Dataset` (`as_dict`, every pass)
against the WebDataset shards of `export --objects K` (full size, `--crop`, `--crop --resize
SIDE`), read raw with `webdataset` and through Hugging Face `datasets`, and against the COCO
files of `export --format coco`: every pass of every sample bit for bit (the normal included),
the same shape, size, material and colour ids (one table: `ids.json` of both exports equals
`Dataset.names`), `category_id` = shape id + 1; the metadata's numbers copied bit for bit
into the shards' records (WebDataset and Hugging Face) and COCO's `attributes`; the COCO files
of all variants merged have disjoint image and annotation ids and load in pycocotools. Prints
one summary line."""
import contextlib, glob, io, json, os, sys
import numpy as np
import webdataset as wds
import datasets
from pycocotools.coco import COCO
import clevrtex

src, full, crop, resized, side, coco_out, k = sys.argv[1:8]
side, k = int(side), int(k)
PASSES = ("depth", "normal", "albedo", "shadow")


def same(a, b, what):
    a, b = np.asarray(a), np.asarray(b)
    assert a.shape == b.shape and a.dtype == b.dtype, (what, a.shape, a.dtype, b.shape, b.dtype)
    if a.tobytes() != b.tobytes():
        bad = np.argwhere(~((a == b) | (np.isnan(a) & np.isnan(b)) if a.dtype.kind == "f" else a == b))
        raise AssertionError(f"{what}: {len(bad)} of {a.size} values differ, first at {bad[0].tolist()}: {a[tuple(bad[0])]} vs {b[tuple(bad[0])]}")


def floats(got, want, what):
    """Numbers copied from the metadata: the same float64, bit for bit."""
    got, want = np.asarray(got, np.float64), np.asarray(want, np.float64)
    assert got.shape == want.shape and got.tobytes() == want.tobytes(), (what, got.tolist(), want.tolist())
    return got.size


ids = json.load(open(os.path.join(full, "ids.json")))
assert ids == json.load(open(os.path.join(coco_out, "ids.json"))), "the WebDataset and COCO id tables differ"
names = ids["names"]
assert json.load(open(os.path.join(full, "index.json")))["names"] == names
variants = sorted({os.path.basename(u).split("-")[0] for u in glob.glob(os.path.join(full, "*.tar"))})
assert len(variants) >= 2, variants

items, metas, n_samples, n_floats, n_objects = {}, {}, 0, 0, 0
for out, crop_, resize in ((full, False, None), (crop, True, None), (resized, True, (side, side))):
    for variant in variants:
        ds = clevrtex.Dataset(src, variant, split="all", crop=crop_, resize=resize, as_dict=True, passes=PASSES, max_objects=k)
        assert ds.names == names, (variant, "Dataset.names is not ids.json's")
        by_stem = {ds.stem(i): i for i in range(len(ds))}
        urls = sorted(glob.glob(os.path.join(out, f"{variant}-*.tar")))
        seen = 0
        for s in wds.WebDataset(urls, shardshuffle=False).map(clevrtex.wds.decode):
            stem = s["stem"]
            item = ds[by_stem[stem]]
            what = (os.path.basename(out), stem)
            same(s["image"], np.round(item["image"] * 255).astype(np.uint8).transpose(1, 2, 0), what + ("image",))
            same(s["mask"], item["mask"][0], what + ("mask",))
            same(s["depth"], item["depth"][0], what + ("depth",))
            same(s["normal"], item["normal"].transpose(1, 2, 0), what + ("normal",))
            same(s["albedo"].astype(np.float32) / np.float32(255), item["albedo"].transpose(1, 2, 0), what + ("albedo",))
            same(s["shadow"], item["shadow"][0], what + ("shadow",))
            for key in ("shape", "size", "material", "color", "bbox", "visibility", "valid"):
                same(s[key], item[key], what + (key,))
            if out == full:
                items[stem] = (s, item)
                meta = s["metadata"]
                metas[stem] = meta
                rec = s["record"]
                for o, m in zip(rec["objects"], meta["objects"]):
                    n_floats += floats(o["rotation"], m["rotation"], what + ("rotation",))
                    n_floats += floats(o["coords_3d"], m["3d_coords"], what + ("3d_coords",))
                    n_floats += floats(o["pixel_coords"], m["pixel_coords"], what + ("pixel_coords",))
                    n_objects += 1
                n_floats += floats(rec["intrinsics"], meta["camera"]["intrinsics"], what + ("intrinsics",))
                n_floats += floats(rec["extrinsics"], meta["camera"]["extrinsics"], what + ("extrinsics",))
            seen += 1
        assert seen == len(ds) > 0, (out, variant, seen, len(ds))
        n_samples += seen

# Hugging Face: every variant's shards at once, the same arrays and numbers.
hf = datasets.load_dataset("webdataset", data_files={"x": sorted(glob.glob(os.path.join(full, "*.tar")))}, split="x")
assert len(hf) == len(items), (len(hf), len(items))
for row in hf:
    d = clevrtex.wds.decode(row)
    s, item = items[d["stem"]]
    for key in ("mask", "depth", "normal", "shadow", "shape", "size", "material", "color"):
        same(d[key], s[key], ("hf", d["stem"], key))
    meta = metas[d["stem"]]
    for o, m in zip(d["record"]["objects"], meta["objects"]):
        floats(o["rotation"], m["rotation"], ("hf", d["stem"]))
        floats(o["coords_3d"], m["3d_coords"], ("hf", d["stem"]))
        floats(o["pixel_coords"], m["pixel_coords"], ("hf", d["stem"]))

# COCO: categories are the shape table; attributes the metadata's numbers; ids unique across
# the variants, so the files merge.
files = sorted(f for f in glob.glob(os.path.join(coco_out, "*.json")) if os.path.basename(f) != "ids.json")
merged = {"images": [], "annotations": [], "categories": None}
numbers = ids["coco"]["variant_numbers"]
for f in files:
    doc = json.load(open(f))
    if merged["categories"] is None:
        merged["categories"] = doc["categories"]
    assert doc["categories"] == merged["categories"], f
    assert [c["name"] for c in doc["categories"]] == names["shape"], f
    assert doc["info"]["attribute_names"] == {t: names[t] for t in ("size", "material", "color")}, f
    by_image = {}
    for img in doc["images"]:
        assert img["id"] == numbers[img["variant"]] * 10**8 + img["index"], img
        by_image[img["id"]] = img["stem"]
    for a in doc["annotations"]:
        stem = by_image[a["image_id"]]
        s, item = items[stem]
        i = a["object_index"]
        assert a["id"] == a["image_id"] * 1000 + i + 1, a["id"]
        assert a["category_id"] - 1 == item["shape"][i], (stem, i, a["category_id"], item["shape"][i])
        attrs, m = a["attributes"], metas[stem]["objects"][i]
        assert names["material"].index(attrs["material"]) == item["material"][i], (stem, i)
        for key in ("rotation", "3d_coords", "pixel_coords"):
            n_floats += floats(attrs[key], m[key], ("coco", stem, key))
    merged["images"] += doc["images"]
    merged["annotations"] += doc["annotations"]
image_ids = [i["id"] for i in merged["images"]]
ann_ids = [a["id"] for a in merged["annotations"]]
assert len(set(image_ids)) == len(image_ids) == len(items), (len(set(image_ids)), len(image_ids), len(items))
assert len(set(ann_ids)) == len(ann_ids), "annotation ids collide across the variants"
with contextlib.redirect_stdout(io.StringIO()):
    coco = COCO()
    coco.dataset = merged
    coco.createIndex()
assert len(coco.imgs) == len(image_ids) and len(coco.anns) == len(ann_ids)
for a in coco.loadAnns(coco.getAnnIds()):
    assert coco.annToMask(a).sum() == a["area"], a["id"]
print(f"variants: {' '.join(variants)} samples: {n_samples} objects: {n_objects} floats: {n_floats} coco: {len(image_ids)} images {len(ann_ids)} annotations")
