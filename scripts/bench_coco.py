"""Speed and memory of `clevrtex export --format coco` (issue 43; figures in
docs/output-format.md, "COCO export").

    python3 scripts/bench_coco.py --clevrtex target/debug/clevrtex --work /tmp/bc [--n 10000]

1. Renders one `full` sample at the variant's own size (skipped when `--work` has it).
2. Makes a dataset of `--n` samples without rendering, as scripts/bench_dataset.py does: that
   sample's PNGs hard-linked under every stem, its metadata written per stem with the index,
   stem and split edited (the position rule of one run of N).
3. Runs the export once untimed (files in the page cache), then `--repeat` times, each in a fresh
   process, and prints wall seconds, CPU seconds (user + system) and the peak resident memory of
   the export, and the size of what it wrote.

Needs only the Python standard library.
"""

import argparse
import json
import os
import shutil
import subprocess
import time


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--clevrtex", required=True)
    ap.add_argument("--work", required=True)
    ap.add_argument("--n", type=int, default=10_000)
    ap.add_argument("--repeat", type=int, default=3)
    a = ap.parse_args()
    src = os.path.join(a.work, "render")
    if not os.path.isdir(os.path.join(src, "clevrtex_full")):
        subprocess.run([a.clevrtex, "generate", "--variant", "full", "-n", "1", "--samples", "4", "--out", src],
                       check=True, stdout=subprocess.DEVNULL)
    folder = os.path.join(src, "clevrtex_full", "0")
    stem0 = "CLEVRTEX_full_000000"
    meta = json.load(open(os.path.join(folder, stem0 + ".json")))
    files = [f for f in os.listdir(folder) if f.startswith(stem0) and f.endswith(".png")]
    fixture = os.path.join(a.work, f"fixture-{a.n}")
    if not os.path.isdir(fixture):
        test, val = int(0.1 * a.n), int(0.2 * a.n)
        for i in range(a.n):
            stem = f"CLEVRTEX_full_{i:06d}"
            d = os.path.join(fixture, "clevrtex_full", str(i // 1000))
            os.makedirs(d, exist_ok=True)
            for f in files:
                os.link(os.path.join(folder, f), os.path.join(d, stem + f[len(stem0):]))
            m = dict(meta, image_index=i, stem=stem, split="test" if i < test else "val" if i < val else "train")
            for k, v in meta.items():
                if k.endswith("_filename") and isinstance(v, str):
                    m[k] = stem + v[len(stem0):]
            with open(os.path.join(d, stem + ".json"), "w") as f:
                json.dump(m, f)
    objects = len(meta["objects"])
    print(f"fixture: {a.n} samples of `full` at {meta['render']['width']}x{meta['render']['height']}, {objects} objects each")
    out = os.path.join(a.work, "coco")
    for run in range(a.repeat + 1):
        shutil.rmtree(out, ignore_errors=True)
        t = time.perf_counter()
        p = subprocess.Popen([a.clevrtex, "export", "--format", "coco", fixture, out], stdout=subprocess.DEVNULL)
        _, status, usage = os.wait4(p.pid, 0)  # this child's own CPU and peak memory
        wall = time.perf_counter() - t
        p.returncode = os.waitstatus_to_exitcode(status)
        if p.returncode != 0:
            raise SystemExit(f"export failed with exit code {p.returncode}")
        cpu = usage.ru_utime + usage.ru_stime
        size = sum(os.path.getsize(os.path.join(out, f)) for f in os.listdir(out))
        if run == 0:
            continue  # the page cache warmed
        print(f"run {run}: {wall:.1f} s wall, {cpu:.1f} s CPU, peak RSS {usage.ru_maxrss / 1024:.0f} MB (ru_maxrss), wrote {size / 1e6:.1f} MB")


if __name__ == "__main__":
    main()
