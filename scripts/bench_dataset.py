"""Speed of `clevrtex.Dataset` (issue 32; figures in docs/python.md, "Speed").

    .venv-test/bin/python scripts/bench_dataset.py --clevrtex target/release/clevrtex --work /tmp/bd

1. Item throughput, rgb + mask at 128x128, one process: `Dataset(crop=False, resize=None,
   return_metadata=False)` against decoding the same two PNGs per sample with Pillow in a plain
   loop (both to a float32 (3, H, W) image in [0, 1] and the ids). The samples: 8 rendered at
   128x128, each copied to `--items / 8` stems.
2. DataLoader (torch, batch 32) over the same with 0 and 2 workers.
3. Opening a dataset of `--open` samples (made without rendering: one rendered sample's PNGs
   hard-linked under every stem, its metadata written per stem with the index, stem and
   split edited): seconds and peak memory of a fresh process doing `Dataset(path, split=...)`.
"""

import argparse
import json
import os
import subprocess
import sys
import time

import numpy as np


def render(clevrtex: str, out: str, n: int, side: int) -> str:
    if not os.path.isdir(os.path.join(out, "clevrtex_clevr")):
        subprocess.run([clevrtex, "generate", "--variant", "clevr", "-n", str(n), "--width", str(side), "--height", str(side),
                        "--samples", "4", "--passes", "rgb,mask", "--out", out], check=True, stdout=subprocess.DEVNULL)
    return os.path.join(out, "clevrtex_clevr", "0")


def copies(src_dir: str, out: str, total: int, link: bool) -> None:
    """`total` samples under `out` made of the samples in `src_dir` (round robin), metadata edited."""
    stems = sorted(f[:-5] for f in os.listdir(src_dir) if f.endswith(".json"))
    metas = {s: json.load(open(os.path.join(src_dir, s + ".json"))) for s in stems}
    test, val = int(0.1 * total), int(0.2 * total)
    for i in range(total):
        s = stems[i % len(stems)]
        new = f"CLEVRTEX_clevr_{i:06}"
        d = os.path.join(out, "clevrtex_clevr", str(i // 1000))
        os.makedirs(d, exist_ok=True)
        for suffix in (".png", "_flat.png"):
            dst = os.path.join(d, new + suffix)
            if not os.path.exists(dst):
                (os.link if link else _copy)(os.path.join(src_dir, s + suffix), dst)
        m = dict(metas[s], image_index=i, stem=new, image_filename=new + ".png", mask_filename=new + "_flat.png",
                 split="test" if i < test else ("val" if i < val else "train"))
        with open(os.path.join(d, new + ".json"), "w") as f:
            json.dump(m, f)


def _copy(a: str, b: str) -> None:
    with open(a, "rb") as f, open(b, "wb") as g:
        g.write(f.read())


def throughput(root: str) -> None:
    import clevrtex
    from PIL import Image

    ds = clevrtex.Dataset(root, "clevr", split="all", crop=False, resize=None, return_metadata=False)
    samples = ds._samples
    n = len(ds)
    best = {}
    for rep in range(3):
        t = time.perf_counter()
        for i in range(n):
            ds[i]
        best["dataset"] = min(best.get("dataset", 1e9), time.perf_counter() - t)
        t = time.perf_counter()
        for _, image, mask, _ in samples:
            img = np.asarray(Image.open(image).convert("RGB")).transpose(2, 0, 1).astype(np.float32) / np.float32(255)
            msk = np.asarray(Image.open(mask))[None]
        best["pillow"] = min(best.get("pillow", 1e9), time.perf_counter() - t)
    assert img.shape == ds[n - 1][1].shape and msk.shape == ds[n - 1][2].shape
    print(f"items: {n} at {img.shape[1]}x{img.shape[2]}, best of 3")
    for k, v in best.items():
        print(f"  {k}: {n / v:.0f} items/s ({1e3 * v / n:.3f} ms/item)")
    print(f"  Dataset / Pillow time: {best['dataset'] / best['pillow']:.2f}x")
    try:
        import torch
        from torch.utils.data import DataLoader
    except ImportError:
        print("  DataLoader: torch not installed")
        return
    torch.set_num_threads(1)
    for workers in (0, 2):
        dl = DataLoader(ds, batch_size=32, num_workers=workers, collate_fn=clevrtex.collate, persistent_workers=workers > 0)
        for _ in dl:  # warm: workers started (and kept), files cached
            pass
        t = time.perf_counter()
        for _ in dl:
            pass
        dt = time.perf_counter() - t
        print(f"  DataLoader batch 32, {workers} workers: {n / dt:.0f} items/s")


def open_time(root: str, split: str) -> None:
    code = (
        "import time, clevrtex\n"
        "t = time.perf_counter()\n"
        f"ds = clevrtex.Dataset({root!r}, 'clevr', split={split!r})\n"
        "dt = time.perf_counter() - t\n"
        "rss = [int(l.split()[1]) for l in open('/proc/self/status') if l.startswith('VmHWM')][0] / 1024\n"
        "print(f'{len(ds)} {dt:.3f} {rss:.0f}')\n"
    )
    n, dt, rss = subprocess.run([sys.executable, "-c", code], check=True, capture_output=True, text=True).stdout.split()
    print(f"open split={split}: {n} samples in {float(dt):.2f} s, peak RSS (VmHWM) of the process {rss} MB")


def main() -> int:
    ap = argparse.ArgumentParser()
    ap.add_argument("--clevrtex", default="clevrtex")
    ap.add_argument("--work", required=True)
    ap.add_argument("--items", type=int, default=400)
    ap.add_argument("--open", type=int, default=50000)
    args = ap.parse_args()
    src = render(args.clevrtex, os.path.join(args.work, "src"), 8, 128)
    items = os.path.join(args.work, "items")
    copies(src, items, args.items, link=False)
    throughput(items)
    big = os.path.join(args.work, "big")
    t = time.perf_counter()
    if not os.path.exists(os.path.join(big, "clevrtex_clevr", str((args.open - 1) // 1000), f"CLEVRTEX_clevr_{args.open - 1:06}.json")):
        copies(src, big, args.open, link=True)
    print(f"made {args.open} samples in {time.perf_counter() - t:.0f} s")
    for split in ("all", "train", "test"):
        open_time(big, split)
    return 0


if __name__ == "__main__":
    sys.exit(main())
