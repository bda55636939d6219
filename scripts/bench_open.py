"""Time opening a large dataset with `clevrtex.Dataset` (metadata only, no rendering).

Makes a fixture of N samples (default 50,000) from one sample of a real dataset: its metadata
copied with the index, stem and split of each sample (the split of one run of N: test the
first int(0.1 N), val up to int(0.2 N)), and the image and mask as empty files (opening a
`Dataset` lists them, never reads them). Then times `clevrtex.Dataset(FIXTURE, VARIANT,
split=...)` for each split, with the files in the page cache (after a first, untimed open)
and reports the peak resident memory of the process.

    python scripts/bench_open.py SOURCE_DATASET FIXTURE_DIR [N]

SOURCE_DATASET: an output folder of `clevrtex generate` (its first sample is copied).
"""

import glob
import json
import os
import resource
import sys
import time

import clevrtex


def main() -> None:
    src, fixture = sys.argv[1], sys.argv[2]
    n = int(sys.argv[3]) if len(sys.argv) > 3 else 50_000
    first = sorted(glob.glob(os.path.join(src, "clevrtex_*", "*", "CLEVRTEX_*_??????.json")))[0]
    meta = json.load(open(first))
    variant = meta["variant"]
    t0 = time.perf_counter()
    if not os.path.isdir(fixture):
        test, val = int(0.1 * n), int(0.2 * n)
        for i in range(n):
            stem = f"CLEVRTEX_{variant}_{i:06d}"
            folder = os.path.join(fixture, f"clevrtex_{variant}", str(i // 1000))
            os.makedirs(folder, exist_ok=True)
            meta.update(
                image_index=i,
                stem=stem,
                image_filename=f"{stem}.png",
                mask_filename=f"{stem}_flat.png",
                split="test" if i < test else "val" if i < val else "train",
            )
            with open(os.path.join(folder, stem + ".json"), "w") as f:
                json.dump(meta, f)
            for suffix in (".png", "_flat.png"):
                open(os.path.join(folder, stem + suffix), "w").close()
        print(f"fixture: {n} samples ({len(json.dumps(meta))} bytes of metadata each) in {time.perf_counter() - t0:.1f} s")
    clevrtex.Dataset(fixture, variant, split="train")  # warm the page cache
    for split in ("train", "val", "test"):
        t = time.perf_counter()
        ds = clevrtex.Dataset(fixture, variant, split=split)
        print(f"open split={split}: {len(ds)} samples in {time.perf_counter() - t:.2f} s")
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    print(f"peak resident memory: {peak:.0f} MB")


if __name__ == "__main__":
    main()
