"""Minimal EXR reader for checking the bridge's output (plain python3, dev only).

Reads single-part scanline EXRs with NONE, RLE, ZIPS or ZIP compression. `python3 exr_dump.py FILE.exr` prints every channel's min/max/mean, the
distinct values of IndexOB, and NaN/Inf counts.
"""

import math
import struct
import sys
import zlib


def _unrle(data):
    out = bytearray()
    i = 0
    while i < len(data):
        n = struct.unpack_from("b", data, i)[0]
        i += 1
        if n < 0:
            out += data[i:i - n]
            i -= n
        else:
            out += data[i:i + 1] * (n + 1)
            i += 1
    return out


def _undo_zip(data, expected, rle=False):
    t = bytearray(_unrle(data) if rle else zlib.decompress(data))
    for i in range(1, len(t)):
        t[i] = (t[i - 1] + t[i] - 128) & 0xFF
    half = (len(t) + 1) // 2
    out = bytearray(len(t))
    out[0::2] = t[:half]
    out[1::2] = t[half:]
    assert len(out) == expected, (len(out), expected)
    return bytes(out)


def read(path):
    with open(path, "rb") as f:
        buf = f.read()
    assert buf[:4] == b"\x76\x2f\x31\x01", "not an EXR"
    flags = struct.unpack_from("<I", buf, 4)[0]
    assert not flags & 0x1A00, "tiled/deep/multipart not supported"
    pos = 8
    header = {}
    while buf[pos] != 0:
        end = buf.index(b"\0", pos)
        name = buf[pos:end].decode()
        pos = end + 1
        end = buf.index(b"\0", pos)
        typ = buf[pos:end].decode()
        pos = end + 1
        size = struct.unpack_from("<i", buf, pos)[0]
        pos += 4
        header[name] = (typ, buf[pos:pos + size])
        pos += size
    pos += 1
    chans = []
    raw = header["channels"][1]
    p = 0
    while raw[p] != 0:
        end = raw.index(b"\0", p)
        cname = raw[p:end].decode()
        ptype = struct.unpack_from("<i", raw, end + 1)[0]
        chans.append((cname, ptype))
        p = end + 1 + 16
    comp = header["compression"][1][0]
    xmin, ymin, xmax, ymax = struct.unpack("<4i", header["dataWindow"][1])
    w, h = xmax - xmin + 1, ymax - ymin + 1
    lines = {0: 1, 1: 1, 2: 1, 3: 16}[comp]
    nchunks = (h + lines - 1) // lines
    offsets = struct.unpack_from("<%dQ" % nchunks, buf, pos)
    sizes = {0: 4, 1: 2, 2: 4}
    data = {c: [0.0] * (w * h) for c, _ in chans}
    for off in offsets:
        y, n = struct.unpack_from("<ii", buf, off)
        block = buf[off + 8:off + 8 + n]
        nl = min(lines, ymax - y + 1)
        expected = nl * w * sum(sizes[t] for _, t in chans)
        if comp != 0 and n < expected:
            block = _undo_zip(block, expected, rle=(comp == 1))
        q = 0
        for line in range(nl):
            row = (y - ymin + line) * w
            for c, t in chans:
                fmt = {0: "I", 1: "e", 2: "f"}[t]
                vals = struct.unpack_from("<%d%s" % (w, fmt), block, q)
                q += w * sizes[t]
                data[c][row:row + w] = vals
    return w, h, data


def main():
    w, h, data = read(sys.argv[1])
    print("%s: %dx%d" % (sys.argv[1], w, h))
    for c, vals in sorted(data.items()):
        bad = sum(1 for v in vals if math.isnan(v) or math.isinf(v))
        fin = [v for v in vals if not (math.isnan(v) or math.isinf(v))]
        line = "  %-28s min %-12.6g max %-12.6g mean %-12.6g nan/inf %d" % (
            c, min(fin), max(fin), sum(fin) / len(fin), bad)
        if "IndexOB" in c:
            distinct = sorted(set(vals))
            line += " distinct %s" % distinct[:20]
        print(line)


if __name__ == "__main__":
    main()
