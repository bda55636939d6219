"""Speed of `clevrtex eval`: the CLI, the Python package and the public evaluator, one run.

    ./scripts/setup.sh --test-venv && cargo build --release
    .venv-test/bin/python scripts/bench_eval.py --images 10000 --out /tmp/bench-eval

Makes a synthetic dataset in the published layout (320x240, up to 10 objects; predictions are
the true masks relabelled with 20% of the pixels changed, as `_mask.png`), then times:
1. `clevrtex eval` (release) on the files, every metric of the `clevrtex` protocol;
2. `clevrtex.evaluate` on the same masks already in memory as numpy arrays (no PNG decode);
3. the public evaluator, `CLEVRTEX_Evaluator.update` in batches of 64 (the numpy port in
   tests/eval_reference/harness.py: the original needs PyTorch, see docs/eval.md);
4. one batch of 64 128x128 soft predictions (11 slots): `clevrtex.Evaluator.update` against
   the public `update`, the median of several repeats.
Prints one JSON object.
"""

import argparse
import json
import resource
import os
import subprocess
import sys
import tempfile
import time

import numpy as np
from PIL import Image

ROOT = os.path.abspath(os.path.join(os.path.dirname(__file__), ".."))
sys.path.insert(0, os.path.join(ROOT, "tests", "eval_reference"))
import harness  # noqa: E402

import clevrtex  # noqa: E402


def make_dataset(out, n, rng):
    gt = os.path.join(out, "gt", "clevrtex_full")
    preds = os.path.join(out, "preds")
    last = os.path.join(gt, str((n - 1) // 1000), f"CLEVRTEX_full_{n - 1:06}.json")
    if os.path.exists(last):  # made by an earlier run with the same --out and --images
        return os.path.join(out, "gt"), preds
    os.makedirs(preds, exist_ok=True)
    yy, xx = np.mgrid[0:240, 0:320]
    for i in range(n):
        d = os.path.join(gt, str(i // 1000))
        os.makedirs(d, exist_ok=True)
        stem = f"CLEVRTEX_full_{i:06}"
        mask = np.zeros((240, 320), np.uint8)
        img = np.stack([xx * 0.5, yy * 0.8, np.full_like(xx, 90)], -1).astype(np.float64)
        objects = []
        for k in range(1, int(rng.integers(3, 11)) + 1):
            cx, cy, r = rng.integers(70, 250), rng.integers(40, 200), rng.integers(12, 40)
            inside = (xx - cx) ** 2 + (yy - cy) ** 2 < r * r
            mask[inside] = k
            img[inside] = rng.integers(0, 256, 3)
            objects.append({"material": f"m{k % 4}", "shape": "sphere", "size": "large", "rotation": 0.0})
        Image.fromarray(img.astype(np.uint8), "RGB").save(os.path.join(d, stem + ".png"))
        Image.fromarray(mask, "L").save(os.path.join(d, stem + "_flat.png"))
        with open(os.path.join(d, stem + ".json"), "w") as f:
            json.dump({"ground_material": "g", "objects": objects}, f)
    return os.path.join(out, "gt"), preds


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--images", type=int, default=10000)
    ap.add_argument("--out", default=None)
    ap.add_argument("--cli", default=os.path.join(os.environ.get("CARGO_TARGET_DIR", os.path.join(ROOT, "target")), "release", "clevrtex"))
    ap.add_argument("--public-images", type=int, default=None, help="score only this many with the public evaluator")
    a = ap.parse_args()
    rng = np.random.default_rng(0)
    out = a.out or tempfile.mkdtemp(prefix="bench-eval-")
    t0 = time.perf_counter()
    gt, preds = make_dataset(out, a.images, rng)
    ds = clevrtex.Dataset(gt, "full", split="all", return_metadata=True)
    truth = np.stack([ds[i][2][0] for i in range(len(ds))]).astype(np.uint8)
    images = np.stack([ds[i][1] for i in range(len(ds))])
    metas = [ds[i][3] for i in range(len(ds))]
    pred = np.where(rng.random(truth.shape) < 0.2, rng.integers(0, 11, truth.shape), (truth * 7 + 3) % 11).astype(np.uint8)
    for i in range(len(ds)):
        Image.fromarray(pred[i], "L").save(os.path.join(preds, f"CLEVRTEX_full_{i:06}_mask.png"))
    setup = time.perf_counter() - t0
    n = len(ds)

    c0 = resource.getrusage(resource.RUSAGE_CHILDREN)
    t0 = time.perf_counter()
    subprocess.run([a.cli, "eval", preds, gt, "--split", "all", "--bootstrap", "0", "--json", os.path.join(out, "cli.json")], check=True, capture_output=True)
    cli_s = time.perf_counter() - t0
    c1 = resource.getrusage(resource.RUSAGE_CHILDREN)
    cli_cpu = (c1.ru_utime - c0.ru_utime) + (c1.ru_stime - c0.ru_stime)

    t0, p0 = time.perf_counter(), time.process_time()
    r = clevrtex.evaluate(pred, truth, protocol="clevrtex")
    pkg_s, pkg_cpu = time.perf_counter() - t0, time.process_time() - p0
    with open(os.path.join(out, "cli.json")) as f:
        cli_metrics = json.load(f)["metrics"]
    assert abs(r["mIoU"] - cli_metrics["mIoU"]) < 1e-9 and abs(r["ARI_FG"] - cli_metrics["ARI_FG"]) < 1e-9

    # The public evaluator on batches of 64 one-hot predictions with images (as in training).
    m_pub = a.public_images or n
    public = harness.ClevrTexEvaluator()
    t0, p0 = time.perf_counter(), time.process_time()
    for s in range(0, m_pub, 64):
        e = min(s + 64, m_pub)
        pm = (pred[s:e, None] == np.arange(11)[None, :, None, None]).astype(np.float32)[:, :, None]
        public.update(images[s:e], pm, images[s:e], truth[s:e, None].astype(np.int64), metas[s:e])
    pub_s, pub_cpu = time.perf_counter() - t0, time.process_time() - p0

    # One batch of 64 soft predictions: the package's Evaluator against the public update.
    b = 64
    masks = rng.random((b, 11, 1, 128, 128)).astype(np.float32)
    tm = truth[:b, None].astype(np.int64)
    img = images[:b]

    def timed(f, reps):
        ts, cs = [], []
        for _ in range(reps):
            t, c = time.perf_counter(), time.process_time()
            f()
            ts.append(time.perf_counter() - t)
            cs.append(time.process_time() - c)
        return float(np.median(ts)), float(np.median(cs))

    (ours_b, ours_bc) = timed(lambda: clevrtex.Evaluator().update(img, masks, img, tm, metas[:b]), 11)
    (pub_b, pub_bc) = timed(lambda: harness.ClevrTexEvaluator().update(img, masks, img, tm, metas[:b]), 3)
    res = {
        "images": n,
        "cpus": os.cpu_count(),
        "setup_s": round(setup, 1),
        "cli_s": round(cli_s, 3),
        "cli_images_per_s": round(n / cli_s, 1),
        "cli_cpu_s": round(cli_cpu, 2),
        "package_s": round(pkg_s, 3),
        "package_images_per_s": round(n / pkg_s, 1),
        "package_cpu_s": round(pkg_cpu, 2),
        "public_images": m_pub,
        "public_s": round(pub_s, 3),
        "public_images_per_s": round(m_pub / pub_s, 1),
        "public_cpu_s": round(pub_cpu, 2),
        "package_vs_public_cpu_per_image": round((pub_cpu / m_pub) / (pkg_cpu / n), 1),
        "package_vs_public": round((n / pkg_s) / (m_pub / pub_s), 1),
        "cli_vs_public": round((n / cli_s) / (m_pub / pub_s), 1),
        "batch64_package_ms": round(ours_b * 1e3, 2),
        "batch64_public_ms": round(pub_b * 1e3, 1),
        "batch64_speedup": round(pub_b / ours_b, 1),
        "batch64_package_cpu_ms": round(ours_bc * 1e3, 2),
        "batch64_public_cpu_ms": round(pub_bc * 1e3, 1),
        "batch64_cpu_speedup": round(pub_bc / ours_bc, 1),
    }
    print(json.dumps(res, indent=1))


if __name__ == "__main__":
    main()
