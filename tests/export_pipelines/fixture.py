"""A dataset written without Blender for the export tests (tests/export.rs): `fixture.py ROOT VARIANT:N ...`.
Each sample: 40x30, 2-4 objects as random blobs (object 0 hidden under object 1 in every
fourth), a palette mask, a random RGB image, 16-bit depth (2.5 m + 0.1 m per id, background
65535), metadata as `clevrtex generate` writes its keys (names from the variant's tables, `color`
null where the variant has none, `blender_compat` on odd samples only), the split recorded by
the position rule."""
import json, os, sys
import numpy as np
from PIL import Image
from clevrtex import _native
root, specs = sys.argv[1], sys.argv[2:]
W, H = 40, 30
for spec in specs:
    variant, n = spec.split(":")
    n = int(n)
    shapes, sizes, materials, colours = _native.variant_names(variant)
    test, val = int(0.1 * n), int(0.2 * n)
    for i in range(n):
        rng = np.random.default_rng(1000 * len(variant) + i)
        stem = f"CLEVRTEX_{variant}_{i:06d}"
        d = os.path.join(root, f"clevrtex_{variant}", str(i // 1000))
        os.makedirs(d, exist_ok=True)
        k = 2 + i % 3
        mask = np.zeros((H, W), np.uint8)
        for j in range(k):
            y0, x0 = rng.integers(0, H - 6), rng.integers(0, W - 6)
            r = mask[y0:y0 + rng.integers(3, 12), x0:x0 + rng.integers(3, 14)]
            r[rng.random(r.shape) < 0.8] = j + 1
        if i % 4 == 3:
            mask[mask == 1] = 2  # object 0 hidden
        objects = []
        for j in range(k):
            ys, xs = np.nonzero(mask == j + 1)
            objects.append({
                "shape": shapes[(i + j) % len(shapes)], "size": sizes[j % len(sizes)][0],
                "material": materials[(i + 3 * j) % len(materials)],
                "color": colours[(i + j) % len(colours)] if colours else None,
                "rotation": 12.5 * j, "3d_coords": [j, -j, 0.5], "pixel_coords": [10.0 + j, 12.0, 9.0],
                "index": j, "visible_pixels": int(len(ys)),
                "bbox": [int(xs.min()), int(ys.min()), int(xs.max()), int(ys.max())] if len(ys) else None,
            })
        im = Image.fromarray(mask, "P")
        im.putpalette([v for c in range(256) for v in ((c * 37) % 256, (c * 91) % 256, (c * 53) % 256)])
        im.save(os.path.join(d, stem + "_flat.png"))
        Image.fromarray(rng.integers(0, 256, (H, W, 3), dtype=np.uint8)).save(os.path.join(d, stem + ".png"))
        depth = np.where(mask > 0, 2500 + 100 * mask.astype(np.int64), 65535).astype(np.uint16)
        Image.fromarray(depth).save(os.path.join(d, stem + "_depth_0001.png"))
        meta = {
            "num_objects": k, "split": "test" if i < test else "val" if i < val else "train",
            "image_index": i, "variant": variant, "stem": stem, "ground_material": materials[i % len(materials)],
            "objects": objects, "render": {"width": W, "height": H},
            "camera": {"intrinsics": [[70.0, 0, 20.0], [0, 70.0, 15.0], [0, 0, 1]], "extrinsics": np.eye(4).tolist()},
            "passes": {"depth": {"scale": 0.001, "background": 65535}},
            "image_filename": stem + ".png", "mask_filename": stem + "_flat.png", "depth_filename": stem + "_depth_0001.png",
            "normal_filename": None, "albedo_filename": None, "shadow_filename": None,
        }
        if i % 2:
            meta["blender_compat"] = {"coat": True}
        with open(os.path.join(d, stem + ".json"), "w") as f:
            json.dump(meta, f)
