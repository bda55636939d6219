"""Tests of the Python package `clevrtex` (run by `tests/python_package.rs`, or by hand:
`.venv-test/bin/python -m pytest crates/python/tests` with `CLEVRTEX_BIN` naming the CLI).

The package must equal the public evaluator (the numpy port in tests/eval_reference/harness.py)
and the CLI on the same fixtures, read datasets like the public loader, and release the GIL.
"""

import json
import os
import subprocess
import sys
import tempfile
import threading
import time

import numpy as np
import pytest

import clevrtex

ROOT = os.path.abspath(os.path.join(os.path.dirname(__file__), "..", "..", ".."))
sys.path.insert(0, os.path.join(ROOT, "tests", "eval_reference"))
import harness  # noqa: E402

GT = os.path.join(ROOT, "tests", "data", "eval", "gt")
NPZ = os.path.join(ROOT, "tests", "data", "eval", "preds", "npz")
PUBLIC = ["mIoU", "mIoU_fg", "mIoU_gt", "ARI", "ARI_FG", "MSE", "DICE", "DICE_FG", "acc"]


class FakeTensor:
    """Quacks like a torch tensor (detach, cpu, numpy) without torch."""

    def __init__(self, a):
        self.a = a

    def detach(self):
        return self

    def cpu(self):
        return self

    def numpy(self):
        return self.a


def batch(rng, b=6, h=16, w=16, k=5, kt=4, soft=True):
    truth = np.kron(rng.integers(0, kt, size=(b, 1, h // 2, w // 2)), np.ones((1, 1, 2, 2), dtype=np.int64))
    truth[:, :, 0, 0] = 1  # at least one object pixel: the public mIoU_fg is NaN otherwise
    truth[:, :, 0, 1] = 0
    if soft:
        masks = rng.random((b, k, 1, h, w)).astype(np.float32)
        masks[rng.random((b, k, 1, h, w)) < 0.3] = 0.5  # ties
    else:
        perm = rng.permutation(max(k, kt))
        labels = np.where(rng.random(truth.shape) < 0.2, rng.integers(0, k, truth.shape), perm[truth] % k)
        masks = (labels[:, None] == np.arange(k)[None, :, None, None, None]).astype(np.float32)[:, :, 0]
    img_t = rng.random((b, 3, h, w)).astype(np.float32)
    img_p = rng.random((b, 3, h, w)).astype(np.float32)
    meta = [
        {"ground_material": f"g{i % 2}", "objects": [{"material": f"m{j % 3}", "shape": "cube", "size": "large", "rotation": 1.0} for j in range(kt)]}
        for i in range(b)
    ]
    return img_p, masks, img_t, truth, meta


@pytest.mark.parametrize("soft,have_bg", [(True, True), (False, True), (True, False)])
def test_evaluator_equals_the_public_evaluator(soft, have_bg):
    rng = np.random.default_rng(7)
    ours = clevrtex.Evaluator(masks_have_background=have_bg)
    public = harness.ClevrTexEvaluator(masks_have_background=have_bg)
    for step in range(4):
        img_p, masks, img_t, truth, meta = batch(rng, soft=soft)
        if not have_bg:
            masks = masks / np.float32(masks.shape[1])
        public.update(img_p, masks, img_t, truth, meta)
        args = (img_p, masks, img_t, truth, meta)
        if step % 2:
            args = tuple(FakeTensor(a) for a in args[:4]) + (meta,)
        ours.update(*args)
    for name in PUBLIC:
        want = public.statistic(name)
        assert np.isfinite(want), name
        assert abs(ours.statistic(name) - want) <= 1e-6, (name, ours.statistic(name), want)
    for name, tag in [("obj_iou", "material"), ("obj_mse", "material"), ("ground_iou", "ground_material")]:
        got, want = ours.statistic(name, tag), public.statistic(name, tag)
        assert [k for k, _ in got] == [k for k, _ in want], name
        assert all(abs(a - b) <= 1e-6 for (_, a), (_, b) in zip(got, want)), (name, got, want)


def test_evaluator_takes_one_hot_truth():
    rng = np.random.default_rng(8)
    img_p, masks, img_t, truth, _ = batch(rng)
    one_hot = (truth == np.arange(6)[None, :, None, None]).astype(np.float32)  # padded to 6
    a, b = clevrtex.Evaluator(), harness.ClevrTexEvaluator()
    a.update(img_p, masks, img_t, one_hot)
    b.update(img_p, masks, img_t, one_hot)
    for name in PUBLIC:
        assert abs(a.statistic(name) - b.statistic(name)) <= 1e-6, name


def test_evaluator_names_an_unknown_statistic():
    """A misspelt statistic is an error naming the known ones (it was NaN, as if nothing had
    been added); a known one before any update is NaN, an added one its mean."""
    ev = clevrtex.Evaluator()
    with pytest.raises(ValueError, match="unknown statistic `nope`; known: .*mIoU"):
        ev.statistic("nope")
    with pytest.raises(ValueError, match="unknown statistic"):
        ev.statistic("nope", "shape")
    assert np.isnan(ev.statistic("ARI_FG"))
    assert ev.statistic("obj_iou", "shape") == []
    ev.add_statistic("mine", 2.0)
    assert ev.statistic("mine") == 2.0


def layouts(a):
    """`a` as C order, Fortran order, a strided view and big-endian: the Rust half reads C-order
    arrays of native dtypes in place, the Python half copies the others once."""
    strided = np.zeros(a.shape[:-1] + (2 * a.shape[-1],), a.dtype)[..., ::2]
    strided[...] = a
    return [a, np.asfortranarray(a), strided, a.astype(a.dtype.newbyteorder(">"))]


def stats_of(ev):
    """Every statistic of an evaluator (NaN as None, so equal results compare equal)."""
    nan = lambda v: None if v != v else v  # noqa: E731
    return {name: nan(ev.statistic(name)) for name in clevrtex.METRICS} | {
        (name, tag): ev.statistic(name, tag) for name, tag in [("obj_iou", "material"), ("obj_mse", "shape"), ("ground_mse", "ground_material")]
    }


def test_every_dtype_and_layout_scores_alike():
    rng = np.random.default_rng(11)
    img_p, masks, img_t, truth, meta = batch(rng, b=5, k=6)
    masks[rng.random(masks.shape) < 0.02] = np.nan  # NaN is the maximum, first one wins
    ref = clevrtex.Evaluator()
    ref.update(img_p, masks, img_t, truth, meta)
    want = stats_of(ref)
    public = harness.ClevrTexEvaluator()
    public.update(img_p, masks, img_t, truth, meta)
    for name in PUBLIC:
        assert abs(ref.statistic(name) - public.statistic(name)) <= 1e-6, name
    # Masks: float32 or float64 (rounded to float32, as before), in any layout.
    mask_variants = layouts(masks) + layouts(masks.astype(np.float64))
    for m in mask_variants:
        ev = clevrtex.Evaluator()
        ev.update(img_p, m, img_t, truth, meta)
        assert stats_of(ev) == want, (m.dtype, m.flags.c_contiguous)
    # Truth: every integer dtype, bool, integral floats; images float64 or mixed.
    truth_variants = [truth.astype(t) for t in (np.uint8, np.int8, np.uint16, np.int16, np.uint32, np.int32, np.uint64, np.float32, np.float64)]
    truth_variants += layouts(truth)
    for t in truth_variants:
        ev = clevrtex.Evaluator()
        ev.update(img_p, masks, img_t, t, meta)
        assert stats_of(ev) == want, (t.dtype, t.flags.c_contiguous)
    # Images: float64 (read as float32, as before), mixed dtypes, Fortran order.
    for a, b in [(img_p.astype(np.float64), img_t.astype(np.float64)), (img_p.astype(np.float64), img_t), (np.asfortranarray(img_p), img_t)]:
        ev = clevrtex.Evaluator()
        ev.update(a, masks, b, truth, meta)
        assert stats_of(ev) == want, (a.dtype, b.dtype)
    # evaluate: soft masks of either float dtype and ids of any dtype, in any layout.
    t3, m4 = truth[:, 0], masks[:, :, 0]
    want_e = clevrtex.evaluate(m4, t3, metrics=clevrtex.METRICS, per_image=True)
    for m in layouts(m4) + [m4.astype(np.float64)]:
        assert clevrtex.evaluate(m, t3, metrics=clevrtex.METRICS, per_image=True) == want_e, m.dtype
    labels = np.argmax(m4, axis=1)
    want_l = clevrtex.evaluate(labels, t3, per_image=True)
    for p in layouts(labels) + [labels.astype(np.uint8), labels.astype(np.int16), labels.astype(np.float32)]:
        assert clevrtex.evaluate(p, t3, per_image=True) == want_l, p.dtype
    assert clevrtex.evaluate(labels > 0, t3 > 0) == clevrtex.evaluate((labels > 0) * 1, (t3 > 0) * 1)


def test_bad_ids_are_named():
    t = np.zeros((2, 4, 4), np.int64)
    for dtype, bad in [(np.int64, -3), (np.int8, -1), (np.uint16, 1024), (np.uint64, 2**40), (np.float64, 4096.0)]:
        p = np.zeros((2, 4, 4), dtype)
        p[1, 2, 3] = bad
        with pytest.raises(ValueError, match=f"`preds` holds segment id `{int(bad)}`, outside 0..1024"):
            clevrtex.evaluate(p, t)
        with pytest.raises(ValueError, match=f"`gt` holds segment id `{int(bad)}`, outside 0..1024"):
            clevrtex.evaluate(t, p)
    with pytest.raises(ValueError, match="`true_masks` holds segment id `-1`"):
        clevrtex.Evaluator().update(np.zeros((2, 3, 4, 4)), np.zeros((2, 3, 4, 4)), np.zeros((2, 3, 4, 4)), t[:, None] - 1)
    with pytest.raises(ValueError, match="`gt` must hold integer segment ids"):
        clevrtex.evaluate(t, t + 0.5)


def test_soft_masks_are_read_in_place():
    # A copy of the masks (as `tobytes` made before) would show in the traced peak.
    import tracemalloc

    rng = np.random.default_rng(5)
    img_p, _, img_t, truth, meta = batch(rng, b=8, h=64, w=64)
    masks = rng.random((8, 11, 1, 64, 64)).astype(np.float32)
    clevrtex.Evaluator().update(img_p, masks, img_t, truth, meta)  # warm up
    tracemalloc.start()
    try:
        clevrtex.Evaluator().update(img_p, masks, img_t, truth, meta)
        _, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    assert peak < masks.nbytes / 4, f"update allocated {peak} bytes for {masks.nbytes} bytes of masks"


def cli(*args):
    exe = os.environ.get("CLEVRTEX_BIN")
    if not exe:
        pytest.skip("CLEVRTEX_BIN is not set (tests/python_package.rs sets it)")
    with tempfile.TemporaryDirectory() as d:
        j = os.path.join(d, "r.json")
        subprocess.run([exe, "eval", *args, "--json", j], check=True, capture_output=True)
        with open(j) as f:
            return json.load(f)


def test_evaluate_equals_the_cli_on_the_fixture_dataset():
    ds = clevrtex.Dataset(GT, "vbg", split="all", return_metadata=False)
    assert len(ds) == 10
    truth = np.stack([ds[i][2][0] for i in range(len(ds))]).astype(np.int64)
    # The fixture's predictions have different numbers of masks: one call per image.
    masks = [np.load(os.path.join(NPZ, f"CLEVRTEX_vbg_{i:06}.npz"))["masks"] for i in range(len(ds))]
    assert len({m.shape[0] for m in masks}) > 1
    names = [m for m in clevrtex.METRICS if m != "MSE"]
    for no_bg in (False, True):
        flags = ["--no-background"] if no_bg else []
        r = cli(NPZ, GT, "--split", "all", "--bootstrap", "0", "--metrics", "all", *flags)
        per = [clevrtex.evaluate(m[None], t[None], metrics=names, no_background=no_bg) for m, t in zip(masks, truth)]
        got = {}
        for m in names:
            vals = [p[m] for p in per if p[m] is not None]
            got[m] = float(np.mean(vals)) if vals else None
        for m in names:
            want = r["metrics"][m]
            assert (got[m] is None) == (want is None), m
            if want is not None:
                assert abs(got[m] - want) <= 1e-9, (m, got[m], want)


def test_evaluate_equals_the_reference_protocols():
    cases = harness.make_cases()
    for c in cases:
        truth = np.array(c["truth"], dtype=np.int64).reshape(1, c["h"], c["w"])
        masks = np.array(c["masks"], dtype=np.float32).reshape(1, c["k"], c["h"], c["w"])
        got = clevrtex.evaluate(masks, truth, metrics=list(c["expected"]))
        for m, want in c["expected"].items():
            if want == "refused":
                continue
            assert (got[m] is None) == (want is None), (c["name"], m, got[m], want)
            if want is not None:
                assert abs(got[m] - want) <= 1e-6, (c["name"], m, got[m], want)


def test_protocol_defaults():
    assert clevrtex.protocol_metrics("deepmind") == ["dm_FG_ARI"]
    rng = np.random.default_rng(3)
    t = rng.integers(0, 4, size=(3, 8, 8))
    r = clevrtex.evaluate(t, t, protocol="ocl", per_image=True)
    assert set(r) == set(clevrtex.protocol_metrics("ocl")) | {"per_image"}
    assert r["mBO"] == 1.0 and len(r["per_image"]["mBO"]) == 3
    with pytest.raises(ValueError, match="unknown protocol"):
        clevrtex.evaluate(t, t, protocol="nope")
    with pytest.raises(ValueError, match="segment id `-1`"):
        clevrtex.evaluate(t - 1, t)
    with pytest.raises(ValueError, match=r"\(3, 8, 7\)"):
        clevrtex.evaluate(t[:, :, :7], t)


def test_dataset_equals_the_public_loader():
    ds = clevrtex.Dataset(GT, "vbg", split="all")
    for i in range(len(ds)):
        index, img, msk, meta = ds[i]
        stem = os.path.join(GT, "clevrtex_vbg", "0", f"CLEVRTEX_vbg_{index:06}")
        want_img, want_msk = harness.clevrtex_load(stem + ".png", stem + "_flat.png")
        assert img.dtype == np.float32 and img.shape == (3, 128, 128)
        assert np.array_equal(img, want_img), f"image {index}"
        assert np.array_equal(msk[0], want_msk), f"mask {index}"
        assert set(meta) == {"ground_material", "objects", "stem"}
        assert meta["stem"] == f"CLEVRTEX_vbg_{index:06}"  # issue 43: predictions are named by it
        assert all("color" in o for o in meta["objects"])  # vbg keeps colours
    # Splits as the public loader: test is the first int(0.1 N).
    assert len(clevrtex.Dataset(GT, "vbg", split="test")) == 1
    assert len(clevrtex.Dataset(GT, "vbg", split="train")) == 8
    native = clevrtex.Dataset(GT, "vbg", split="all", crop=False, resize=None)
    assert native[0][1].shape == (3, 30, 40)
    with pytest.raises(ValueError, match="no ground-truth samples"):
        clevrtex.Dataset(GT, "camo")
    with pytest.raises(IndexError, match="index 10 is out of range for a Dataset of 10 samples"):
        ds[10]
    with pytest.raises(IndexError, match="out of range"):
        ds[10**18]
    with pytest.raises(TypeError, match="indexed by an int"):
        ds["0"]


def test_colours_follow_the_variant_config(tmp_path):
    # The variant config's property (it lists `objects.colors`), not a variant name.
    from clevrtex import _native

    assert {v: _native.colour_breakdown(v) for v in ("full", "camo", "vbg", "clevr", "mine")} == {
        "full": False, "camo": False, "vbg": True, "clevr": True, "mine": False,
    }
    # The vbg fixture under clevr and full names: clevr keeps the colours, full drops them.
    src = os.path.join(GT, "clevrtex_vbg", "0")
    for variant, keeps in (("clevr", True), ("full", False)):
        dst = tmp_path / variant / f"clevrtex_{variant}" / "0"
        dst.mkdir(parents=True)
        for name in os.listdir(src):
            data = open(os.path.join(src, name), "rb").read()
            if name.endswith(".json"):
                data = data.replace(b"vbg", variant.encode())
            (dst / name.replace("_vbg_", f"_{variant}_")).write_bytes(data)
        ds = clevrtex.Dataset(str(tmp_path / variant), variant, split="all")
        assert len(ds) == 10
        for i in range(len(ds)):
            objects = ds[i][3]["objects"]
            assert objects and all(("color" in o) == keeps for o in objects), (variant, i)


def test_the_gil_is_released_while_scoring():
    # 300 segments per image: the matching is cubic, so one call takes a while.
    rng = np.random.default_rng(0)
    truth = np.tile((np.arange(64 * 64).reshape(64, 64) // 13) % 300, (16, 1, 1))
    pred = np.where(rng.random(truth.shape) < 0.3, rng.integers(0, 300, truth.shape), (truth * 7 + 3) % 300)
    # Grow the batch until one call takes at least half a second on this machine.
    while True:
        t0 = time.perf_counter()
        clevrtex.evaluate(pred, truth)
        if time.perf_counter() - t0 >= 0.5 or len(truth) >= 1 << 14:
            break
        truth, pred = np.concatenate([truth, truth]), np.concatenate([pred, pred])
    done = threading.Event()
    took = []

    def work():
        t0 = time.perf_counter()
        clevrtex.evaluate(pred, truth)
        took.append(time.perf_counter() - t0)
        done.set()

    ticks, gaps, last = 0, [], time.perf_counter()
    th = threading.Thread(target=work)
    th.start()
    while not done.is_set():
        ticks += 1
        now = time.perf_counter()
        gaps.append(now - last)
        last = now
    th.join()
    # With the GIL held for the whole call this thread would stall for about its length.
    assert took[0] > 0.25, f"scoring took {took[0]:.3f} s: too short to show anything"
    assert max(gaps) < took[0] / 2, f"this thread stalled {max(gaps):.3f} s of {took[0]:.3f} s"
    assert ticks > 1000


def test_wrong_shapes_and_short_metadata_raise_before_any_state_changes():
    """Issue 21: a wrong-shaped `pred_masks` (batch 4 against 2, H and W swapped) used to be
    reshaped silently into other images' pixels, and a short metadata list raised IndexError
    after the first image was counted. Now ValueError names the shapes, and nothing is counted."""
    rng = np.random.default_rng(3)
    img_p, masks, img_t, truth, meta = batch(rng, b=2, h=16, w=8)
    ev = clevrtex.Evaluator()
    ev.update(img_p, masks, img_t, truth, meta)
    before = {name: (rm.v, rm.n) for name, rm in ev.stats.items()}
    tags_before = repr(ev.tags)
    cases = [
        (np.concatenate([masks, masks]), truth, meta, r"`pred_masks` is \(4, 5, 1, 16, 8\)"),
        (masks.transpose(0, 1, 2, 4, 3).copy(), truth, meta, r"`pred_masks` is \(2, 5, 1, 8, 16\)"),
        (masks, truth.transpose(0, 1, 3, 2).copy(), meta, r"`true_masks` is \(2, 1, 8, 16\)"),
        (masks, truth, meta[:1], r"`true_metadata` has 1 entries but the batch has 2 images"),
        (masks, truth, [meta[0], {"objects": "cube"}], r"`true_metadata\[1\]\['objects'\]` is a str"),
        (masks, truth, [meta[0], None], r"`true_metadata\[1\]` is a NoneType"),
    ]
    for pm, tm, md, message in cases:
        with pytest.raises(ValueError, match=message):
            ev.update(img_p, pm, img_t, tm, md)
        assert {name: (rm.v, rm.n) for name, rm in ev.stats.items()} == before, message
        assert repr(ev.tags) == tags_before, message


def _zero_png(path, side):
    """A valid greyscale PNG of `side` x `side` zeros: under 1 MB for 30000, gigabytes decoded."""
    import struct
    import zlib

    def chunk(t, d):
        return struct.pack(">I", len(d)) + t + d + struct.pack(">I", zlib.crc32(t + d) & 0xFFFFFFFF)

    z = zlib.compressobj(9)
    row = bytes(side + 1)
    data = b"".join(z.compress(row) for _ in range(side)) + z.flush()
    with open(path, "wb") as f:
        f.write(b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", struct.pack(">IIBBBBB", side, side, 8, 0, 0, 0, 0)) + chunk(b"IDAT", data) + chunk(b"IEND", b""))


def test_dataset_reads_untrusted_samples_within_bounds(tmp_path):
    """Issue 21: `Dataset` decoded a mask whose header declares 30000x30000 (a 1 MB file: 4.5 GB
    decoded, an abort under a 2 GB limit) and read metadata of any size with `open`. Now a PNG's
    size is checked from its header first, metadata is read up to 64 MiB from a regular file,
    and a mask linked out of the dataset is refused when the dataset is opened."""
    import shutil
    import textwrap

    gt = tmp_path / "gt"
    shutil.copytree(GT, gt)
    sub = gt / "clevrtex_vbg" / "0"
    _zero_png(sub / "CLEVRTEX_vbg_000000_flat.png", 30000)
    code = textwrap.dedent(
        f"""
        import resource
        resource.setrlimit(resource.RLIMIT_AS, (2 << 30, 2 << 30))
        import clevrtex
        ds = clevrtex.Dataset({str(gt)!r}, "vbg", split="all")
        try:
            ds[0]
        except ValueError as e:
            print("ValueError:", e)
        """
    )
    env = dict(os.environ, OPENBLAS_NUM_THREADS="1", OMP_NUM_THREADS="1")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120, env=env)
    assert out.returncode == 0, out.stdout + out.stderr
    assert "declares 30000x30000" in out.stdout and "CLEVRTEX_vbg_000000_flat.png" in out.stdout, out.stdout + out.stderr
    shutil.copy(os.path.join(GT, "clevrtex_vbg", "0", "CLEVRTEX_vbg_000000_flat.png"), sub)

    # Metadata over 64 MiB (sparse: no disk) is refused, not read.
    meta = sub / "CLEVRTEX_vbg_000001.json"
    with open(meta, "r+b") as f:
        f.truncate((64 << 20) + 1)
    ds = clevrtex.Dataset(str(gt), "vbg", split="all")
    with pytest.raises(ValueError, match=r"CLEVRTEX_vbg_000001.json` is 67108865 bytes, over the 67108864"):
        ds[1]
    assert ds[0][0] == 0  # the others are read

    # A mask linked out of the dataset: refused by name when the dataset is opened.
    outside = tmp_path / "outside_flat.png"
    mask = sub / "CLEVRTEX_vbg_000002_flat.png"
    os.rename(mask, outside)
    os.symlink(outside, mask)
    with pytest.raises(ValueError, match=r"CLEVRTEX_vbg_000002_flat.png` is a symbolic link leading out"):
        clevrtex.Dataset(str(gt), "vbg", split="all")

    # Files changed after the `Dataset` was made (issue 22's before/after comparison): a deleted
    # metadata file is a FileNotFoundError (errno 2, as `open` gives), a FIFO is not read, and
    # a link swapped in that leads out of the dataset is not followed.
    os.remove(mask)
    shutil.copy(outside, mask)
    ds = clevrtex.Dataset(str(gt), "vbg", split="all")
    meta2 = sub / "CLEVRTEX_vbg_000002.json"
    secret = tmp_path / "secret.json"
    shutil.copy(meta2, secret)
    os.remove(meta2)
    with pytest.raises(FileNotFoundError, match=r"CLEVRTEX_vbg_000002.json` cannot be read") as e:
        ds[2]
    assert e.value.errno == 2 and e.value.filename == str(meta2)
    os.mkfifo(meta2)
    with pytest.raises(ValueError, match=r"CLEVRTEX_vbg_000002.json` is not a regular file .*; not read"):
        ds[2]
    os.remove(meta2)
    os.symlink(secret, meta2)
    with pytest.raises(ValueError, match=r"CLEVRTEX_vbg_000002.json` is a symbolic link leading out of the dataset .*; not followed"):
        ds[2]
    assert ds[3][0] == 3


def test_dataset_reads_nothing_through_a_bucket_swapped_for_a_link(tmp_path):
    """Issue 34: a bucket folder swapped for a link out of the dataset after the `Dataset` was
    made was read through (only a sample's own file was checked for a link). Files are now
    opened relative to a handle on the dataset's root, so the canary is never read."""
    import shutil

    gt = tmp_path / "gt"
    shutil.copytree(GT, gt)
    ds = clevrtex.Dataset(str(gt), "vbg", split="all")
    assert ds[0][0] == 0
    bucket = gt / "clevrtex_vbg" / "0"
    canary = tmp_path / "canary"
    shutil.copytree(bucket, canary)
    os.rename(bucket, gt / "clevrtex_vbg" / "moved")
    os.symlink(canary, bucket)
    for i in range(2):
        with pytest.raises(ValueError, match=r"through a symbolic link leading out of the dataset; not followed"):
            ds[i]


def test_hostile_arrays_and_metadata_are_named(tmp_path):
    """Issue 21's second hostile pass (repro-06, 07, 08): non-numeric arrays, metadata values
    that cannot tag a statistic, and metadata `objects` of the wrong type raise ValueError
    naming the argument or file, before any state changes."""
    import shutil

    rng = np.random.default_rng(5)
    img = rng.random((2, 3, 8, 8), dtype=np.float32)
    ids = rng.integers(0, 3, size=(2, 1, 8, 8))
    for bad in (ids.astype(object), ids.astype(str), ids.astype(np.complex64), ids.astype("datetime64[s]")):
        with pytest.raises(ValueError, match=r"`pred_masks` has dtype .*use a bool, integer or float array"):
            clevrtex.Evaluator().update(img, bad, img, ids)
        with pytest.raises(ValueError, match=r"`preds` has dtype"):
            clevrtex.evaluate(bad[:, 0], ids[:, 0])
    ev = clevrtex.Evaluator()
    meta = [{"ground_material": "a", "objects": []}, {"ground_material": "b", "objects": [{"shape": {1, 2}}]}]
    with pytest.raises(ValueError, match=r"`true_metadata\[1\]\['objects'\]\[0\]\['shape'\]` is a set"):
        ev.update(img, ids, img, ids, meta)
    assert ev.stats["mIoU"].n == 0  # nothing was counted
    with pytest.raises(ValueError, match=r"`true_metadata` is a int"):
        ev.update(img, ids, img, ids, 5)
    gt = tmp_path / "gt"
    shutil.copytree(GT, gt)
    f = gt / "clevrtex_vbg" / "0" / "CLEVRTEX_vbg_000001.json"
    m = json.loads(f.read_text())
    ds = clevrtex.Dataset(str(gt), "vbg", split="all")
    # Refused by the CLI's check of the metadata (`check_metadata`), naming the file and key.
    for objects in (5, None, "abc", [None]):
        f.write_text(json.dumps(dict(m, objects=objects)))
        with pytest.raises(ValueError, match=r"CLEVRTEX_vbg_000001.json` key `objects"):
            ds[1]
    f.write_text("[" * 200000 + "]" * 200000)
    with pytest.raises(ValueError, match=r"CLEVRTEX_vbg_000001.json` is not valid metadata"):
        ds[1]


def test_dataset_follows_no_image_link_swapped_in_and_bounds_resize(tmp_path):
    """Issue 21's third hostile pass: an image or mask replaced by a link out of the dataset
    after the `Dataset` was made was read through it; `resize=(100000, 100000)` killed the
    interpreter (a 30 GB allocation). Both are ValueErrors now."""
    import shutil

    gt = tmp_path / "gt"
    shutil.copytree(GT, gt)
    ds = clevrtex.Dataset(str(gt), "vbg", split="all")
    for name in ("CLEVRTEX_vbg_000003.png", "CLEVRTEX_vbg_000003_flat.png"):
        f = gt / "clevrtex_vbg" / "0" / name
        outside = tmp_path / name
        shutil.copy(f, outside)
        os.remove(f)
        os.symlink(outside, f)
        with pytest.raises(ValueError, match=name + r"` is a symbolic link leading out of the dataset"):
            ds[3]
        os.remove(f)
        shutil.copy(outside, f)
    assert ds[3][0] == 3
    with pytest.raises(ValueError, match=r"`resize` must be 1 to 4096 a side"):
        clevrtex.Dataset(str(gt), "vbg", split="all", resize=(100000, 100000))


def test_the_package_follows_the_cli_limits_and_names_empty_batches(tmp_path):
    """Issue 34: K = 0 or K > 1024 soft masks were scored though `clevrtex eval` refuses them;
    B = 0 or H = W = 0 raised numpy's "cannot reshape"; a deleted mask a bare OSError."""
    rng = np.random.default_rng(0)
    img_p, masks, img_t, truth, _ = batch(rng, b=2, h=4, w=4, k=3)
    ev = clevrtex.Evaluator()
    with pytest.raises(ValueError, match=r"`pred_masks` has 0 masks: need 1 to 1024"):
        ev.update(img_p, masks[:, :0], img_t, truth)
    with pytest.raises(ValueError, match=r"`pred_masks` has 1024 masks: need 1 to 1023 \(at most 1024 slots with the background added"):
        clevrtex.Evaluator(masks_have_background=False).update(img_p, np.zeros((2, 1024, 1, 4, 4), np.float32), img_t, truth)
    with pytest.raises(ValueError, match=r"`pred_masks` has 1025 masks"):
        ev.update(img_p, np.zeros((2, 1025, 1, 4, 4), np.float32), img_t, truth)
    with pytest.raises(ValueError, match=r"holds no images \(B = 0\)"):
        ev.update(img_p[:0], masks[:0], img_t[:0], truth[:0])
    with pytest.raises(ValueError, match=r"images are 0x0 pixels"):
        ev.update(img_p[:, :, :0, :0], masks[..., :0, :0], img_t[:, :, :0, :0], truth[..., :0, :0])
    gt = truth[:, 0]
    with pytest.raises(ValueError, match=r"`preds` has 0 masks"):
        clevrtex.evaluate(np.zeros((2, 0, 4, 4), np.float32), gt)
    with pytest.raises(ValueError, match=r"`preds` has 1025 masks"):
        clevrtex.evaluate(np.zeros((2, 1025, 4, 4), np.float32), gt)
    with pytest.raises(ValueError, match=r"`preds` has 1024 masks: need 1 to 1023"):
        clevrtex.evaluate(np.zeros((2, 1024, 4, 4), np.float32), gt, no_background=True)
    with pytest.raises(ValueError, match=r"`gt` holds no images"):
        clevrtex.evaluate(gt[:0], gt[:0])
    with pytest.raises(ValueError, match=r"`gt` images are 0x0 pixels"):
        clevrtex.evaluate(gt[:, :0, :0], gt[:, :0, :0])
    import shutil

    root = tmp_path / "gt"
    shutil.copytree(GT, root)
    ds = clevrtex.Dataset(str(root), "vbg", split="all")
    mask = root / "clevrtex_vbg" / "0" / "CLEVRTEX_vbg_000002_flat.png"
    os.remove(mask)
    with pytest.raises(FileNotFoundError, match="CLEVRTEX_vbg_000002_flat.png") as e:
        ds[2]
    assert e.value.filename == str(mask)
    # A mask of another PNG mode is named, never read as ids from its colour bytes.
    from PIL import Image

    Image.new("RGB", (40, 30)).save(root / "clevrtex_vbg" / "0" / "CLEVRTEX_vbg_000003_flat.png")
    with pytest.raises(ValueError, match=r"CLEVRTEX_vbg_000003_flat.png` is a 8-bit RGB PNG, but a mask pass must be"):
        ds[3]
