#!/usr/bin/env bash
# CI smoke render: `clevrtex generate` of 4 small images, then check that every file of every
# sample exists, the masks are exact (8-bit palette PNGs whose ids are 0..N with every
# object present) and the metadata parses with the published keys. Builds and uses the debug
# binary (what `cargo test` already built). Needs Blender (see README).
set -euo pipefail
cd "$(dirname "$0")/.."

cargo build --quiet --locked
bin=target/debug/clevrtex
out="$(mktemp -d "${TMPDIR:-/tmp}/clevrtex-smoke.XXXXXX")"
trap 'rm -rf "$out"' EXIT

echo "smoke: generating 4 camo images at 96x72, 4 samples into $out"
"$bin" generate --variant camo -n 4 --seed 1 --width 96 --height 72 --samples 4 --out "$out"

# Check the files as a stranger would: plain Python 3 (a dependency of Debian's Blender)
# with its own minimal PNG reader, no clevrtex code involved.
python3 - "$out" <<'PY'
import json, os, struct, sys, zlib

root = os.path.join(sys.argv[1], "clevrtex_camo", "0")

def png(path):
    """(width, height, bit depth, colour type, rows of raw bytes) of a non-interlaced PNG."""
    data = open(path, "rb").read()
    assert data[:8] == b"\x89PNG\r\n\x1a\n", f"{path}: not a PNG"
    pos, idat, ihdr = 8, b"", None
    while pos < len(data):
        n, kind = struct.unpack(">I4s", data[pos:pos + 8])
        body = data[pos + 8:pos + 8 + n]
        if kind == b"IHDR":
            ihdr = struct.unpack(">IIBBBBB", body)
        elif kind == b"IDAT":
            idat += body
        pos += 12 + n
    w, h, depth, ctype, _, _, interlace = ihdr
    assert interlace == 0, f"{path}: interlaced"
    bpp = {0: 1, 2: 3, 3: 1, 4: 2, 6: 4}[ctype] * depth // 8
    raw, rows, prev = zlib.decompress(idat), [], bytearray(w * bpp)
    stride = w * bpp
    for y in range(h):
        f, line = raw[y * (stride + 1)], bytearray(raw[y * (stride + 1) + 1:(y + 1) * (stride + 1)])
        for i in range(stride):
            a = line[i - bpp] if i >= bpp else 0
            b = prev[i]
            c = prev[i - bpp] if i >= bpp else 0
            if f == 1: line[i] = (line[i] + a) & 255
            elif f == 2: line[i] = (line[i] + b) & 255
            elif f == 3: line[i] = (line[i] + (a + b) // 2) & 255
            elif f == 4:
                p = a + b - c
                pa, pb, pc = abs(p - a), abs(p - b), abs(p - c)
                line[i] = (line[i] + (a if pa <= pb and pa <= pc else b if pb <= pc else c)) & 255
        rows.append(bytes(line))
        prev = line
    return w, h, depth, ctype, rows

keys = ["num_objects", "split", "image_index", "image_filename", "ground_material", "directions",
        "objects", "relationships", "mask_filename", "normal_filename", "albedo_filename",
        "depth_filename", "shadow_filename"]
for i in range(4):
    stem = os.path.join(root, "CLEVRTEX_camo_%06d" % i)
    for suffix in [".png", "_flat.png", "_depth_0001.png", "_normal_0001.png",
                   "_albedo_0001.png", "_shadow_0001.png", ".json"]:
        assert os.path.isfile(stem + suffix), f"missing {stem + suffix}"
    meta = json.load(open(stem + ".json"))
    for k in keys:
        assert k in meta, f"{stem}.json lacks {k}"
    n = meta["num_objects"]
    assert len(meta["objects"]) == n
    w, h, depth, ctype, rows = png(stem + "_flat.png")
    assert (depth, ctype) == (8, 3), f"mask is not an 8-bit palette PNG: depth {depth} type {ctype}"
    counts = [0] * 256
    for row in rows:
        for v in row:
            counts[v] += 1
    used = [v for v in range(256) if counts[v]]
    assert max(used) <= n, f"{stem}: mask id {max(used)} > {n} objects"
    threshold = meta["visibility_threshold_px"]
    for k in range(1, n + 1):
        assert counts[k] > threshold, f"{stem}: object {k} has {counts[k]} px"
        assert meta["objects"][k - 1]["visible_pixels"] == counts[k]
    for suffix, bits in [("_depth_0001.png", 16), ("_normal_0001.png", 16), (".png", 8)]:
        assert png(stem + suffix)[2] == bits, f"{stem}{suffix}: not {bits}-bit"
    assert png(stem + ".png")[3] in (2, 6), f"{stem}.png: not an RGB(A) image"
    assert meta["image_filename"] == os.path.basename(stem) + ".png"
    assert meta["mask_filename"] == os.path.basename(stem) + "_flat.png"
    print(f"smoke: {os.path.basename(stem)} ok: {n} objects, ids exact")

# The public loader's rules (reference section 4): its glob finds the RGB images only (not
# `_flat.png` or the pass PNGs, nor temporaries), with no gaps in the indices.
import glob
found = sorted(glob.glob(os.path.join(sys.argv[1], "**", "CLEVRTEX_camo_??????.png"), recursive=True))
assert [os.path.basename(f) for f in found] == ["CLEVRTEX_camo_%06d.png" % i for i in range(4)], found
leftovers = [f for f in glob.glob(os.path.join(sys.argv[1], "**", "*"), recursive=True) if "clevrtex-tmp" in f]
assert not leftovers, f"temporary files left: {leftovers}"
print("smoke: ok")
PY
