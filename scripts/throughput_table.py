#!/usr/bin/env python3
"""The project's one table of CPU-seconds per image (issue 35): variant x preset x size.

Each cell runs `clevrtex generate -n N --workers 1 --threads 1` (every pass, the visibility
check and rejected layouts included) into a fresh temporary folder and reads the CPU-seconds
(user + system) of the run and its Blender worker from `getrusage(RUSAGE_CHILDREN)`. CPU time
is what a shared machine's load disturbs least (wall time grows with the load, CPU time much
less), and it is what a cluster bills: wall time on a host with C free cores running C
single-threaded workers is about N x (CPU-s per image) / C.

    python3 scripts/throughput_table.py [--clevrtex target/debug/clevrtex] [--blender B]
        [--variants clevr,full,camo] [--presets draft,64] [--sizes 320x240] [-n 2]
        [--markdown FILE]

A preset is a `--quality` name (draft, fast, standard, high, reference) or a number of fixed
samples (`64`: the configs' default). "CPU-s per image" divides the whole run by N, so it
includes one Blender start (given apart, from the run's own summary, as wall seconds) per N
images. The load average is printed before and after: say it with the table.
"""

import argparse
import os
import re
import resource
import subprocess
import sys
import tempfile
import time


def children_cpu():
    r = resource.getrusage(resource.RUSAGE_CHILDREN)
    return r.ru_utime + r.ru_stime


def run_cell(exe, blender, variant, preset, size, n, seed):
    width, height = size
    with tempfile.TemporaryDirectory(prefix="clevrtex-table-") as out:
        cmd = [exe, "generate", "--variant", variant, "-n", str(n), "--seed", str(seed),
               "--width", str(width), "--height", str(height), "--workers", "1",
               "--threads", "1", "--device", "cpu", "--out", out]
        if preset.isdigit():
            cmd += ["--samples", preset]
        else:
            cmd += ["--quality", preset]
        if blender:
            cmd += ["--blender", blender]
        before = children_cpu()
        t = time.monotonic()
        proc = subprocess.run(cmd, capture_output=True, text=True)
        wall = time.monotonic() - t
        cpu = children_cpu() - before
    if proc.returncode != 0:
        sys.exit(f"error: `{' '.join(cmd)}` exited {proc.returncode}:\n{proc.stderr[-2000:]}")
    start = re.search(r"blender start\s+([0-9.]+) s", proc.stdout)
    rejects = re.search(r"\((\d+) rejected layout", proc.stdout)
    return {
        "cpu_per_image": cpu / n,
        "wall_per_image": wall / n,
        "blender_start": float(start.group(1)) if start else float("nan"),
        "rejects": int(rejects.group(1)) if rejects else 0,
        "command": " ".join(["clevrtex"] + [("OUT" if x == out else x) for x in cmd[1:]]),
    }


def load():
    return "/".join(f"{x:.2f}" for x in os.getloadavg())


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--clevrtex", default="target/debug/clevrtex")
    ap.add_argument("--blender", default=None)
    ap.add_argument("--variants", default="clevr,full,camo")
    ap.add_argument("--presets", default="draft,64")
    ap.add_argument("--sizes", default="320x240")
    ap.add_argument("-n", type=int, default=2)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--markdown", default=None, help="also write the table to this file")
    a = ap.parse_args()
    if a.n < 1:
        sys.exit("error: `-n` must be at least 1\nhint: e.g. `-n 2`")
    sizes = []
    for s in a.sizes.split(","):
        m = re.fullmatch(r"(\d+)x(\d+)", s.strip())
        if not m:
            sys.exit(f"error: size `{s}` is not WIDTHxHEIGHT\nhint: e.g. `--sizes 320x240`")
        sizes.append((int(m.group(1)), int(m.group(2))))
    if not os.access(a.clevrtex, os.X_OK):
        sys.exit(f"error: `{a.clevrtex}` is not an executable\nhint: `cargo build` first, or pass `--clevrtex PATH`")
    lines = [
        f"load average (1/5/15 min) before: {load()}; {os.cpu_count()} core(s)",
        "",
        "| variant | preset | size | CPU-s per image | wall s per image | Blender start (wall s) | rejects |",
        "|---|---|---|---|---|---|---|",
    ]
    print("\n".join(lines), flush=True)
    command = None
    for variant in a.variants.split(","):
        for preset in a.presets.split(","):
            for size in sizes:
                c = run_cell(a.clevrtex, a.blender, variant, preset, size, a.n, a.seed)
                command = command or c["command"]
                label = preset if not preset.isdigit() else f"{preset} spp"
                line = (f"| {variant} | {label} | {size[0]}x{size[1]} | {c['cpu_per_image']:.1f} | "
                        f"{c['wall_per_image']:.1f} | {c['blender_start']:.1f} | {c['rejects']} |")
                print(line, flush=True)
                lines.append(line)
    tail = [
        "",
        f"load average (1/5/15 min) after: {load()}",
        f"each cell: `{command}` (n = {a.n}, CPU of the run and its Blender worker / n)",
    ]
    print("\n".join(tail))
    lines += tail
    if a.markdown:
        with open(a.markdown, "w") as f:
            f.write("\n".join(lines) + "\n")


if __name__ == "__main__":
    main()
