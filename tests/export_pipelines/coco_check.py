"""`coco_check.py OUT SRC`: every COCO file `clevrtex export --format coco SRC OUT` wrote, read by
pycocotools: `annToMask` of every annotation equals the dataset's mask of that object, the box
its extent, the area its pixels, the category its shape, the attributes its metadata; every
visible object has one annotation; the images are the dataset's files; COCOeval of the
annotations against themselves gives AP 1. Prints `variant split images annotations` per file."""
import contextlib, glob, io, json, os, sys
import numpy as np
from PIL import Image
from pycocotools import mask as mu
from pycocotools.coco import COCO
from pycocotools.cocoeval import COCOeval
out, src = sys.argv[1], sys.argv[2]
assert os.path.isfile(os.path.join(out, "ids.json"))  # the dataset's id table, beside the files
for f in sorted(f for f in glob.glob(os.path.join(out, "*.json")) if os.path.basename(f) != "ids.json"):
    with contextlib.redirect_stdout(io.StringIO()):  # pycocotools' progress lines
        coco = COCO(f)
    info = coco.dataset["info"]
    variant, split = info["variant"], info["split"]
    cats = {c["id"]: c["name"] for c in coco.dataset["categories"]}
    n = 0
    for img in coco.dataset["images"]:
        stem = img["stem"]
        folder = os.path.join(src, "clevrtex_" + variant, str(img["index"] // 1000))
        meta = json.load(open(os.path.join(folder, stem + ".json")))
        assert meta["split"] == split == img["split"], (stem, meta["split"], split)
        truth = np.array(Image.open(os.path.join(folder, stem + "_flat.png")))
        assert (img["height"], img["width"]) == truth.shape
        path = img["file_name"] if os.path.isabs(img["file_name"]) else os.path.join(out, img["file_name"])
        assert open(path, "rb").read() == open(os.path.join(folder, stem + ".png"), "rb").read(), stem
        anns = coco.loadAnns(coco.getAnnIds(imgIds=[img["id"]]))
        present = sorted(int(v) for v in np.unique(truth) if v)
        assert [a["object_index"] + 1 for a in anns] == present, (stem, present)
        for a in anns:
            want = (truth == a["object_index"] + 1).astype(np.uint8)
            assert np.array_equal(coco.annToMask(a), want), (stem, a["id"])
            ys, xs = np.nonzero(want)
            extent = [int(xs.min()), int(ys.min()), int(xs.max() - xs.min() + 1), int(ys.max() - ys.min() + 1)]
            assert a["bbox"] == extent and list(mu.toBbox(coco.annToRLE(a))) == extent, (stem, a["bbox"], extent)
            assert a["area"] == int(want.sum()) == int(mu.area(coco.annToRLE(a))) and a["iscrowd"] == 0
            obj = meta["objects"][a["object_index"]]
            assert cats[a["category_id"]] == obj["shape"], (stem, a["category_id"])
            for key in ("size", "material", "color", "rotation", "3d_coords"):
                assert a["attributes"][key] == obj[key], (stem, key)
            n += 1
    # The annotations scored against themselves as detections: every AP is 1.
    dets = [dict(a, score=1.0) for a in coco.dataset["annotations"]]
    for t in ("segm", "bbox"):
        with contextlib.redirect_stdout(io.StringIO()):
            ev = COCOeval(coco, coco.loadRes(dets), t)
            ev.params.areaRng = [[0, 1e10]] * 4
            ev.evaluate()
            ev.accumulate()
            ev.summarize()
        assert abs(ev.stats[0] - 1.0) < 1e-9, (f, t, ev.stats[0])
    print(variant, split, len(coco.dataset["images"]), n)
