"""The per-material parity table of a displaced backdrop (or of the objects) across Blenders
(issue 50; dev only; plain python3).

    python3 blender_scripts/dev/displace_parity_table.py --materials materials.json \
        [--blender blender] [--blender .venv-bpy/bin/python] [--as backdrop|object] \
        [--names a,b,c | --displacing] [--scene tests/data/scenes/full8.json] [--log FILE]

Runs `displace_parity_probe.py` (96x72, 16 spp, seed 0, 1 thread, objects left out for
`--as backdrop`) on every material named (`--displacing`: every catalogue material that
displaces; default: the whole catalogue) on each Blender in turn (default: `blender` and
`.venv-bpy/bin/python`, those that exist; the first is the reference), six materials per
Blender process, and prints a Markdown table: each material's mean linear luminance and mean
depth of the backdrop's pixels (the objects' luminance with `--as object`) on every Blender,
and the ratio to the reference. Exits 1 when one is past the bounds (luminance 3%, depth 1%).
`--log FILE` appends the probe's PROBE lines as they come (and reads lines already there,
so an interrupted run resumes).
"""

import argparse
import json
import os
import subprocess
import sys

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(os.path.dirname(HERE))
PROBE = os.path.join(HERE, "displace_parity_probe.py")
LUMINANCE_BOUND = 0.03
DEPTH_BOUND = 0.01


def command(blender, args):
    if os.path.basename(blender).startswith("python"):
        return [blender, PROBE] + args
    return [blender, "-b", "--factory-startup", "--python-exit-code", "1", "--python", PROBE,
            "--"] + args


def parse(line):
    """(version, material, role, {key: value}) of a PROBE line."""
    w = line.split()
    return w[1], w[2], w[3], dict(x.split("=", 1) for x in w[5:] if "=" in x)


def main():
    p = argparse.ArgumentParser(prog="displace_parity_table.py")
    p.add_argument("--materials", required=True)
    p.add_argument("--blender", action="append", default=[])
    p.add_argument("--as", dest="role", default="backdrop", choices=["backdrop", "object"])
    p.add_argument("--names", default="")
    p.add_argument("--displacing", action="store_true")
    p.add_argument("--scene", default=os.path.join(ROOT, "tests/data/scenes/full8.json"))
    p.add_argument("--log", default=None)
    args = p.parse_args()
    with open(args.materials, "r", encoding="utf-8") as f:
        catalogue = json.load(f)["materials"]
    names = [n for n in args.names.split(",") if n] or sorted(
        n for n, r in catalogue.items() if r.get("displaces") or not args.displacing)
    blenders = args.blender or [b for b in ("blender", os.path.join(ROOT, ".venv-bpy/bin/python"))
                                if b == "blender" or os.path.exists(b)]
    key = "lum_bd" if args.role == "backdrop" else "lum_obj"
    seen = {}  # (blender index, material) -> values
    lines = []
    if args.log and os.path.exists(args.log):
        lines = [l for l in open(args.log) if l.startswith("PROBE ")]
    versions = []
    for i, blender in enumerate(blenders):
        done = {parse(l)[1] for l in lines if l.startswith("PROBE ")
                and parse(l)[2] == args.role and l.split()[4] == "-#%d" % i}
        todo = [n for n in names if n not in done]
        for k in range(0, len(todo), 6):
            extra = ["--materials", args.materials, "--scene", args.scene, "--as", args.role]
            if args.role == "backdrop":
                extra.append("--no-objects")
            for n in todo[k:k + 6]:
                extra += ["--material", n]
            out = subprocess.run(command(blender, extra), stdout=subprocess.PIPE,
                                 stderr=subprocess.STDOUT, text=True)
            got = [l for l in out.stdout.splitlines() if l.startswith("PROBE ")]
            if out.returncode != 0 or not got:
                sys.exit("%s failed:\n%s" % (blender, out.stdout[-2000:]))
            # Tag each line with the Blender's index (the `sets` column is `-` here).
            got = [l.replace(" - ", " -#%d " % i, 1) + "\n" for l in got]
            lines += got
            if args.log:
                with open(args.log, "a") as f:
                    f.writelines(got)
        for l in lines:
            ver, name, role, kv = parse(l)
            if role == args.role and l.split()[4] == "-#%d" % i:
                seen[(i, name)] = kv
                if len(versions) <= i:
                    versions.append(ver)
    head = "| material | " + " | ".join(
        "%s luminance, depth m%s" % (v, "" if j == 0 else " (/ %s)" % versions[0])
        for j, v in enumerate(versions)) + " |"
    print(head)
    print("|---" * (len(versions) + 1) + "|")
    past = 0
    for n in names:
        ref = seen.get((0, n))
        cells = []
        for j in range(len(versions)):
            kv = seen.get((j, n))
            if kv is None or ref is None:
                cells.append("-")
                continue
            lum, depth = float(kv[key]), float(kv["depth_bd"])
            if j == 0:
                cells.append("%.4f, %.3f" % (lum, depth))
                continue
            dl = lum / float(ref[key]) - 1.0
            dd = depth / float(ref["depth_bd"]) - 1.0
            bad = abs(dl) > LUMINANCE_BOUND or abs(dd) > DEPTH_BOUND
            past += bad
            cells.append("%.4f (%+.1f%%), %.3f (%+.3f%%)%s" % (
                lum, 100 * dl, depth, 100 * dd, " **past**" if bad else ""))
        print("| `%s` | %s |" % (n, " | ".join(cells)))
    print("\n%d of %d past the bounds (luminance %.0f%%, depth %.0f%%)" % (
        past, len(names), 100 * LUMINANCE_BOUND, 100 * DEPTH_BOUND), file=sys.stderr)
    sys.exit(1 if past else 0)


if __name__ == "__main__":
    main()
