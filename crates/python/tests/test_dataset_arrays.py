"""`clevrtex.Dataset(..., as_dict=True)` and `clevrtex.collate` (issue 32) on a hand-made
dataset whose every value is known: the passes decoded to their units, per-object masks and
visibility, metadata arrays in the returned image's frame, pickling for DataLoader workers,
and every bad input named. (The real-render, real-torch run is examples/train_toy.py, run by
tests/python_package.rs.)"""

import json
import multiprocessing
import os
import pickle
import struct
import zlib

import numpy as np
import pytest

import clevrtex

W, H, N = 40, 30, 10  # image size, samples
STEM = "CLEVRTEX_clevr_{:06}"


def _png(path, a, bits):
    """A grey (H, W) or RGB (H, W, 3) PNG of 8 or 16 bits from the array `a`."""
    a = np.asarray(a)
    colour = 2 if a.ndim == 3 else 0
    h, w = a.shape[:2]
    raw = a.astype(">u2" if bits == 16 else "u1").reshape(h, -1).view(np.uint8).reshape(h, -1)
    data = b"".join(b"\x00" + row.tobytes() for row in raw)

    def chunk(t, d):
        return struct.pack(">I", len(d)) + t + d + struct.pack(">I", zlib.crc32(t + d) & 0xFFFFFFFF)

    with open(path, "wb") as f:
        f.write(b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", struct.pack(">IIBBBBB", w, h, bits, colour, 0, 0, 0)) + chunk(b"IDAT", zlib.compress(data)) + chunk(b"IEND", b""))


def _sample(d, i, passes=("depth", "normal", "albedo", "shadow"), total=N):
    """Sample `i` of `total`: objects 1 and 2 are rectangles, object 3 (when i is odd) lies
    outside the centre crop. Its recorded split is the position rule's for `total`."""
    stem = os.path.join(d, STEM.format(i))
    rng = np.random.default_rng(i)
    mask = np.zeros((H, W), np.uint8)
    mask[8:16, 10:20] = 1
    mask[18:24, 22:30] = 2
    n = 2
    if i % 2:
        mask[0:3, 0:3] = 3  # outside the crop (side 24 from (8, 3))
        n = 3
    _png(stem + ".png", rng.integers(0, 256, (H, W, 3)), 8)
    _png(stem + "_flat.png", mask, 8)
    depth = np.full((H, W), 65535, np.uint16)
    depth[mask > 0] = 2500  # 2.5 m
    depth[mask == 0] = 65535
    depth[:, :5] = 7000  # 7 m
    _png(stem + "_depth_0001.png", depth, 16)
    normal = np.full((H, W, 3), 32768, np.uint16)
    normal[mask == 1] = (65535, 32768, 32768)  # +x (about)
    _png(stem + "_normal_0001.png", normal, 16)
    _png(stem + "_albedo_0001.png", np.full((H, W, 3), 51, np.uint8), 8)
    _png(stem + "_shadow_0001.png", np.where(mask == 2, 255, 0), 8)
    objects = []
    for k in range(n):
        objects.append({
            "shape": ["cube", "sphere", "cylinder"][k], "size": ["large", "small", "medium"][k],
            "material": "rubber", "color": ["red", "blue", "cyan"][k], "rotation": 10.0 * k,
            "3d_coords": [k, -k, 0.5], "pixel_coords": [15.0 + k, 12.0, 9.0], "visible_pixels": int((mask == k + 1).sum()),
        })
    meta = {
        "num_objects": n, "split": "test" if i < int(0.1 * total) else ("val" if i < int(0.2 * total) else "train"), "image_index": i,
        "ground_material": "plain", "objects": objects,
        "render": {"width": W, "height": H},
        "camera": {"intrinsics": [[70.0, 0, 20.0], [0, 70.0, 15.0], [0, 0, 1]], "extrinsics": np.eye(4).tolist()},
        "image_filename": STEM.format(i) + ".png", "mask_filename": STEM.format(i) + "_flat.png",
    }
    for p in ("depth", "normal", "albedo", "shadow"):
        meta[f"{p}_filename"] = STEM.format(i) + f"_{p}_0001.png" if p in passes else None
    with open(stem + ".json", "w") as f:
        json.dump(meta, f)


@pytest.fixture
def data(tmp_path):
    d = tmp_path / "data" / "clevrtex_clevr" / "0"
    d.mkdir(parents=True)
    for i in range(N):
        _sample(str(d), i)
    return str(tmp_path / "data")


def _ds(data, **kw):
    args = dict(split="all", as_dict=True, max_objects=4, passes=("depth", "normal", "albedo", "shadow"))
    args.update(kw)
    return clevrtex.Dataset(data, "clevr", **args)


def test_passes_decode_to_their_units(data):
    it = _ds(data, crop=False, resize=None)[1]
    assert it["image"].shape == (3, H, W) and it["image"].dtype == np.float32
    assert it["mask"].shape == (1, H, W) and it["mask"].dtype == np.uint8
    m = it["mask"][0]
    d = it["depth"]
    assert d.shape == (1, H, W) and d.dtype == np.float32
    assert np.all(d[0][(m > 0) & (np.arange(W) >= 5)] == np.float32(2.5)) and np.all(d[0][:, :5] == np.float32(7.0))
    assert np.all(np.isposinf(d[0][(m == 0) & (np.arange(W) >= 5)]))  # background: +inf
    n = it["normal"]
    assert n.shape == (3, H, W) and np.allclose(n[:, m == 1].T, [1, 1.5e-5, 1.5e-5], atol=1e-4)
    assert np.all(n[:, m == 0] == 0)  # background: the zero vector
    assert np.allclose(it["albedo"], 0.2) and it["albedo"].shape == (3, H, W)
    assert np.array_equal(it["shadow"][0], (m == 2).astype(np.float32))


def test_objects_and_camera_in_the_returned_frame(data):
    ds = _ds(data, resize=(48, 48))  # crop: side 24 from (8, 3), scale 2
    it = ds[1]
    assert ds.names["shape"][:3] == ["cube", "sphere", "cylinder"]
    assert it["num_objects"] == 3 and list(it["valid"]) == [True, True, True, False]
    # Object 3 lies outside the crop: in the scene, not visible.
    assert list(it["visibility"]) == [True, True, False, False]
    om = it["object_masks"]
    assert om.shape == (4, 48, 48) and om.dtype == np.bool_
    assert np.array_equal(om[0], it["mask"][0] == 1) and not om[2:].any()
    assert list(it["bbox"][0]) == [(10 - 8) * 2, (8 - 3) * 2, (20 - 8) * 2 - 1, (16 - 3) * 2 - 1]
    assert list(it["bbox"][3]) == [0, 0, 0, 0]
    assert [ds.names["shape"][s] for s in it["shape"][:3]] == ["cube", "sphere", "cylinder"]
    assert list(it["shape"][3:]) == [-1] and list(it["color"][:3]) == [ds.names["color"].index(c) for c in ("red", "blue", "cyan")]
    assert it["scale"][1] == np.float32(ds.scales["small"]) and it["rotation"][2] == 20
    assert np.allclose(it["coords_3d"][2], [2, -2, 0.5])
    assert np.allclose(it["pixel_coords"][0], [(15 - 8) * 2, (12 - 3) * 2, 9])
    assert list(it["visible_pixels"][:2]) == [80, 48]
    assert np.allclose(it["intrinsics"], [[140, 0, (20 - 8) * 2], [0, 140, (15 - 3) * 2], [0, 0, 1]])
    assert it["extrinsics"].shape == (4, 4) and it["ground_material"] == ds.names["material"].index("plain")
    assert it["metadata"]["objects"][0]["shape"] == "cube"


def _first_index(ds):
    return int(ds[0]["index"])


def test_collate_and_workers(data):
    ds = _ds(data)
    b = clevrtex.collate([ds[0], ds[1], ds[2]], tensors=False)
    assert b["image"].shape == (3, 3, 128, 128) and b["object_masks"].shape == (3, 4, 128, 128)
    assert b["index"].tolist() == [0, 1, 2] and b["depth"].dtype == np.float32
    assert isinstance(b["metadata"], list) and len(b["metadata"]) == 3
    t = clevrtex.collate([clevrtex.Dataset(data, "clevr", split="all")[i] for i in range(2)], tensors=False)
    assert t[1].shape == (2, 3, 128, 128) and isinstance(t[3], list)
    # A Dataset pickles (DataLoader's spawn workers) and reads alike in another process.
    assert _first_index(pickle.loads(pickle.dumps(ds))) == 0
    with multiprocessing.get_context("spawn").Pool(2) as pool:
        assert pool.map(_first_index, [ds, ds]) == [0, 0]
    with pytest.raises(ValueError, match="cannot stack arrays of shapes"):
        clevrtex.collate([np.zeros(2), np.zeros(3)], tensors=False)


def test_bad_input_is_named(data, tmp_path):
    with pytest.raises(ValueError, match="unknown pass `flow`"):
        _ds(data, passes=("flow",))
    with pytest.raises(ValueError, match="unknown split `dev`"):
        _ds(data, split="dev")
    for k in (0, -1, 2.5, True):
        with pytest.raises(ValueError, match="`max_objects` must be"):
            _ds(data, max_objects=k)
    with pytest.raises(ValueError, match="need `as_dict=True`"):
        clevrtex.Dataset(data, "clevr", split="all", passes=("depth",))
    with pytest.raises(ValueError, match=r"3 objects, more than `max_objects` = 2"):
        _ds(data, max_objects=2)[1]
    sub = os.path.join(data, "clevrtex_clevr", "0")
    # A pass the dataset does not have: named when the Dataset is made.
    for i in range(N):
        _sample(sub, i, passes=("depth",))
    with pytest.raises(ValueError, match="has no `normal` pass"):
        _ds(data, passes=("depth", "normal"))
    # A pass file gone after: FileNotFoundError naming it; a wrong layout: ValueError.
    ds = _ds(data, passes=("depth",))
    os.remove(os.path.join(sub, STEM.format(3) + "_depth_0001.png"))
    with pytest.raises(FileNotFoundError, match=STEM.format(3) + "_depth_0001.png"):
        ds[3]
    _png(os.path.join(sub, STEM.format(4) + "_depth_0001.png"), np.zeros((H, W), np.uint8), 8)
    with pytest.raises(ValueError, match="is a 8-bit grey PNG, but the depth pass is 16-bit grey"):
        ds[4]
    # Metadata without a field the arrays need.
    path = os.path.join(sub, STEM.format(5) + ".json")
    meta = json.load(open(path))
    del meta["objects"][1]["3d_coords"]
    json.dump(meta, open(path, "w"))
    with pytest.raises(ValueError, match=r"000005.json` has no key \['3d_coords'\]"):
        ds[5]
    meta["objects"][1]["3d_coords"] = [0, 0, 0]
    meta["objects"][1]["shape"] = "pyramid"
    json.dump(meta, open(path, "w"))
    with pytest.raises(ValueError, match=r"`objects\[1\].shape` is 'pyramid', not in the `shape` name table"):
        ds[5]
    assert _ds(data, passes=("depth",), names={"shape": ["cube", "sphere", "cylinder", "pyramid"]})[5]["shape"][1] == 3
    # A render size that is not the image's (the crop's frame would be wrong), or not a number.
    meta["objects"][1]["shape"] = "cube"
    # (Not a number: refused by the CLI's check of the metadata, shared since issue 42.)
    for bad, what in (
        ({"width": 64, "height": H}, r"000005.json` key `render` gives a .* image, but the image file is 40 x 30"),
        ({"width": "40", "height": H}, r"000005.json` key `render.width` is \"40\", not a whole number from 1 to 4096"),
    ):
        meta["render"] = bad
        json.dump(meta, open(path, "w"))
        with pytest.raises(ValueError, match=what):
            ds[5]
    # An empty split names the sizes found.
    small = tmp_path / "small" / "clevrtex_clevr" / "0"
    small.mkdir(parents=True)
    for i in range(4):
        _sample(str(small), i, total=4)
    with pytest.raises(ValueError, match=r"the `test` split of `.*small` is empty: it has 4 samples in all \(test 0, val 0, train 4\)"):
        clevrtex.Dataset(str(tmp_path / "small"), "clevr", split="test")


def test_user_materials_of_the_manifest_are_in_the_material_name_table(data):
    """Issue 41: a dataset rendered with `--materials DIR` names user materials its run
    manifest records; `as_dict=True` gives them ids after the built-in ones (which keep
    theirs) instead of refusing them as unknown."""
    builtin = _ds(data).names["material"]
    path = os.path.join(data, "clevrtex_clevr", "0", STEM.format(3) + ".json")
    meta = json.load(open(path))
    meta["objects"][1]["material"] = "Bricks01"
    json.dump(meta, open(path, "w"))
    with pytest.raises(ValueError, match=r"`objects\[1\].material` is 'Bricks01', not in the `material` name table"):
        _ds(data)[3]
    manifest = {
        "format": "clevrtex-manifest", "version": 1, "variant": "clevr", "seed": 0, "config_hash": "0" * 16,
        "start": 0, "end": N, "total": N, "shard": [0, 1], "passes": ["rgb", "mask"], "tool_version": "0.1.0",
        "blender_version": "3.4.1", "command": ["clevrtex", "generate"], "finished": False, "files": {},
        "user_materials": {"Bricks01": {"file": "Bricks01.blend", "group": "Bricks01", "xxh3": "0123456789abcdef"}},
    }
    json.dump(manifest, open(os.path.join(data, "clevrtex_clevr", f"MANIFEST-0-{N}-0of1.json"), "w"))
    ds = _ds(data)
    assert ds.names["material"] == builtin + ["Bricks01"]
    it = ds[3]
    assert ds.names["material"][it["material"][1]] == "Bricks01"
    assert ds.names["material"][it["material"][0]] == "rubber"


def _eval(preds, data):
    """`clevrtex eval PREDS DATA --protocol native` (the CLI of this build) as its JSON."""
    import subprocess
    import tempfile

    exe = os.environ.get("CLEVRTEX_BIN")
    if not exe:
        pytest.skip("CLEVRTEX_BIN is not set (tests/python_package.rs sets it)")
    with tempfile.TemporaryDirectory() as d:
        j = os.path.join(d, "r.json")
        r = subprocess.run([exe, "eval", preds, data, "--variant", "clevr", "--split", "all", "--protocol", "native", "--bootstrap", "0", "--json", j], capture_output=True, text=True)
        assert r.returncode == 0, r.stderr
        with open(j) as f:
            return json.load(f)


def test_stems_and_predictions_clevrtex_eval_reads(data, tmp_path):
    # Issue 43: every item carries its stem, and `write_predictions` writes a batch under the
    # names `clevrtex eval` reads: the true masks and images score perfectly.
    ds = clevrtex.Dataset(data, "clevr", split="all", crop=False, resize=None)
    index, img, msk, meta = ds[3]
    assert meta["stem"] == ds.stem(3) == STEM.format(index)
    item = _ds(data)[5]
    assert item["stem"] == STEM.format(5) and item["metadata"]["stem"] == STEM.format(5)
    batch = clevrtex.collate([_ds(data)[0], _ds(data)[1]], tensors=False)
    assert batch["stem"] == [STEM.format(0), STEM.format(1)] and batch["mask"].shape[0] == 2
    stems = [ds.stem(i) for i in range(len(ds))]
    masks = np.stack([ds[i][2] for i in range(len(ds))])  # (B, 1, H, W) ids
    images = np.stack([ds[i][1] for i in range(len(ds))])  # (B, 3, H, W) in [0, 1]
    png = str(tmp_path / "png")
    written = clevrtex.write_predictions(png, stems, masks, recon=images)
    assert sorted(os.listdir(png)) == sorted(written_name for s in stems for written_name in (s + "_mask.png", s + "_recon.png"))
    assert written[:2] == [os.path.join(png, stems[0] + "_mask.png"), os.path.join(png, stems[0] + "_recon.png")]
    # Soft masks (B, K, H, W), argmax over K, as a model gives them; `.npz` with the recon.
    soft = (masks == np.arange(4)[None, :, None, None]).astype(np.float32)
    npz = str(tmp_path / "npz")
    clevrtex.write_predictions(npz, stems, soft, recon=images.transpose(0, 2, 3, 1), format="npz")
    for preds in (png, npz):
        r = _eval(preds, data)
        assert r["metrics"]["mIoU"] == 1.0 and r["metrics"]["ARI"] == 1.0, (preds, r["metrics"])
        assert r["metrics"]["MSE"] < 1e-9, (preds, r["metrics"])  # 8-bit PNG: exact; float32: rounding
    with pytest.raises(ValueError, match="stem '../x' is not a plain file name"):
        clevrtex.write_predictions(png, ["../x"], masks[:1])
    with pytest.raises(ValueError, match="2 stems for 10 masks"):
        clevrtex.write_predictions(png, stems[:2], masks)
    with pytest.raises(ValueError, match="unknown format `jpg`"):
        clevrtex.write_predictions(png, stems, masks, format="jpg")
    with pytest.raises(ValueError, match="`recon` is"):
        clevrtex.write_predictions(str(tmp_path / "none"), stems, masks, recon=images[:, :2])
    assert not os.path.exists(tmp_path / "none")


def test_write_predictions_refuses_a_planted_link_and_leaves_its_target(tmp_path):
    # A link planted at a prediction's name, or as the folder, is refused before anything is
    # written and never written through: its target keeps its bytes; no temporary is left.
    masks = np.zeros((1, 4, 5), np.uint8)
    victim = tmp_path / "victim"
    victim.write_bytes(b"keep me")
    out = tmp_path / "preds"
    out.mkdir()
    os.symlink(victim, out / "a_mask.png")
    with pytest.raises(ValueError, match="a_mask.png` is a symbolic link"):
        clevrtex.write_predictions(str(out), ["a"], masks)
    assert victim.read_bytes() == b"keep me"
    assert os.listdir(out) == ["a_mask.png"] and os.path.islink(out / "a_mask.png")
    linked = tmp_path / "linked"
    os.symlink(out, linked)
    with pytest.raises(ValueError, match="linked` is a symbolic link"):
        clevrtex.write_predictions(str(linked), ["b"], masks)
    assert os.listdir(out) == ["a_mask.png"]
    # Without the link, the file is written, atomically, and nothing else is left.
    os.unlink(out / "a_mask.png")
    assert clevrtex.write_predictions(str(out), ["a"], masks) == [str(out / "a_mask.png")]
    assert os.listdir(out) == ["a_mask.png"] and not os.path.islink(out / "a_mask.png")
    assert victim.read_bytes() == b"keep me"
