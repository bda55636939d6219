"""The building blocks of catalogue materials, one function per block of materials/blocks.json.

A block takes the node graph `g`, the pattern coordinates `p` (a vector socket in world units
in the object's frame, already scaled and offset per instance), the layer's resolved
parameters `L` (every default filled by clevrtex-materials) and the per-material context
`ctx` (the object-space normal, the last layout's cell id). It returns a dict:

- `fac`: 0..1, the palette coordinate (required);
- `height`: relief, roughly 0..1 (default: none);
- `gap`: 0..1, 1 in mortar/grout/seams, drawn with `gap_color` (default: none);
- `mask`: 0..1, where the layer is present at all (spots, scratches; default: everywhere);
- `color`: a colour that replaces the palette (image and graph blocks only);
- `cell`, `inside`: set by layout blocks so later layers can vary per cell.

The table `BLOCKS` at the end must list exactly the blocks of materials/blocks.json (the
test `materials::bridge_block_table_matches_the_block_schema` in tests/materials.rs checks
it).
"""

import math


def _tangent_edge(g, ctx, d, axis):
    """Widen `d` (distance to a lattice plane across `axis`) where the surface runs along that
    plane: the trace of a plane on a surface at angle a is 1/sin(a) wider, so dividing by
    sqrt(1 - n_axis^2) keeps mortar lines the same width on every face and on spheres."""
    n = ctx["normal_xyz"][axis]
    s = g.sqrt(g.mx(g.sub(1.0, g.mul(n, n)), 1e-4))
    return g.div(d, s)


def solid(g, p, L, ctx):
    return {"fac": 0.0}


def noise(g, p, L, ctx):
    sx, sy, sz = L["stretch"]
    q = p if (sx, sy, sz) == (1, 1, 1) else g.vmath("MULTIPLY", p, (sx, sy, sz))
    fac, _ = g.noise(q, L["scale"], L["detail"], L["detail_roughness"], L["distortion"])
    if L["ridged"]:
        fac = g.sub(1.0, g.abs(g.madd(fac, 2.0, -1.0)))
        fac = g.pow(fac, 3.0)
    if L["second_scale"] > 0:
        f2, _ = g.noise(p, L["second_scale"], 2.0, 0.5, 0.0)
        fac = g.math("MULTIPLY", fac, g.madd(f2, 2.0, 0.0), clamp=True)
    return {"fac": fac, "height": fac}


def cells(g, p, L, ctx):
    q = p
    if L["distortion"] > 0:
        _, c = g.noise(p, L["scale"] * 1.5, 2.0, 0.5, 0.0)
        q = g.vmath("ADD", p, g.vscale(g.vmath("SUBTRACT", c, (0.5, 0.5, 0.5)),
                                        L["distortion"] / L["scale"]))
    f1 = g.voronoi(q, L["scale"], "F1", L["randomness"])
    edge = g.voronoi(q, L["scale"], "DISTANCE_TO_EDGE", L["randomness"])["Distance"]
    cell = g.sep(f1["Color"])[0]
    half = L["gap"] * 0.5
    gap = g.smooth(half + 0.02, max(half - 0.02, 0.0), edge) if L["gap"] > 0 else 0.0
    if L["roundness"] > 0:
        h = g.smooth(half, half + 0.5 * L["roundness"], edge)
    else:
        h = g.sub(1.0, gap)
    fac = cell if L["fac"] == "id" else g.clamp01(f1["Distance"])
    return {"fac": fac, "height": h, "gap": gap, "cell": cell, "inside": g.sub(1.0, gap)}


def bricks(g, p, L, ctx):
    sx, sy, sz = L["size"]
    q = p
    if L["edge_noise"] > 0:
        _, c = g.noise(p, 1.0 / min(sx, sy, sz), 2.0, 0.5, 0.0)
        amp = L["edge_noise"] * 0.25 * min(sx, sy, sz)
        q = g.vmath("ADD", p, g.vscale(g.vmath("SUBTRACT", c, (0.5, 0.5, 0.5)), amp))
    x, y, z = g.sep(q)
    off = L["offset"]
    iz = g.floor(g.div(z, sz))
    y2 = g.madd(iz, off * sy, y)
    iy = g.floor(g.div(y2, sy))
    x2 = g.madd(g.add(iy, iz), off * sx, x)
    ix = g.floor(g.div(x2, sx))

    def edge(v, s, axis):
        f = g.frac(g.div(v, s))
        d = g.mul(g.sub(0.5, g.abs(g.sub(f, 0.5))), s)
        return _tangent_edge(g, ctx, d, axis)

    d = g.mn(g.mn(edge(x2, sx, 0), edge(y2, sy, 1)), edge(z, sz, 2))
    half = L["gap"] * 0.5
    aa = max(0.15 * L["gap"], 0.001)
    gap = g.smooth(half + aa, half - aa, d) if L["gap"] > 0 else 0.0
    cell = g.white(g.comb(ix, iy, iz))
    bevel = L["bevel"] * 0.25 * min(sx, sy, sz)
    h = g.smooth(half, half + bevel, d) if bevel > 0 else g.sub(1.0, gap)
    if L["jitter"] > 0:
        h = g.mul(h, g.sub(1.0, g.mul(cell, L["jitter"])))
    fac = cell
    if L["fac_noise"] > 0:
        n, _ = g.noise(p, 3.0 / min(sx, sy, sz), 3.0, 0.6, 0.0)
        fac = g.lerp(cell, n, L["fac_noise"])
    return {"fac": fac, "height": h, "gap": gap, "cell": cell, "inside": g.sub(1.0, gap)}


def wood(g, p, L, ctx):
    _, c = g.noise(g.vmath("MULTIPLY", p, (0.15, 1.0, 1.0)), 2.0, 3.0, 0.5, 0.0)
    q = g.vmath("ADD", p, g.vscale(g.vmath("SUBTRACT", c, (0.5, 0.5, 0.5)),
                                    L["figure"] / L["ring_scale"] * 3.0))
    x, y, z = g.sep(q)
    r = g.sqrt(g.add(g.mul(y, y), g.mul(z, z)))
    rings = g.frac(g.mul(r, L["ring_scale"]))
    fac = g.pow(rings, 1.0 + 4.0 * L["sharpness"])
    if L["grain"] > 0:
        streak, _ = g.noise(g.vmath("MULTIPLY", p, (1.0, 30.0, 30.0)), 4.0, 3.0, 0.6, 0.0)
        fac = g.lerp(fac, streak, L["grain"])
    return {"fac": fac, "height": g.mul(fac, 0.3)}


def veins(g, p, L, ctx):
    w1 = g.wave(p, L["scale"], L["distortion"], L["detail"])
    w2 = g.wave(g.vmath("ADD", p, (3.1, 7.7, 1.3)), L["scale"] * 2.3, L["distortion"] * 1.3,
                L["detail"])
    v1 = g.smooth(L["width"], 0.0, w1)
    v2 = g.smooth(L["width"] * 0.6, 0.0, w2)
    fac = g.mx(v1, g.mul(v2, 0.6))
    return {"fac": fac, "height": g.mul(fac, -0.2), "mask": fac}


def weave(g, p, L, ctx):
    s = L["scale"]
    x, y, z = g.sep(p)
    u = g.mul(g.add(x, z), s)
    v = g.mul(g.add(y, z), s)
    kind = L["kind"]
    if kind == "strands":
        t = g.add(u, g.mul(v, 0.6))
        h = g.abs(g.sin(g.mul(t, math.pi)))
        fib, _ = g.noise(g.vmath("MULTIPLY", p, (s * 2.0, s * 0.5, s * 2.0)), 1.0, 2.0, 0.6)
        h = g.lerp(h, fib, L["fibers"] * 0.5)
        return {"fac": h, "height": h}
    if kind == "knit":
        fu = g.frac(u)
        t = g.add(v, g.mul(g.abs(g.sub(fu, 0.5)), 1.2))
        h = g.abs(g.sin(g.mul(t, math.pi)))
        h = g.mul(h, g.sqrt(g.abs(g.sin(g.mul(u, math.pi)))))
        fib, _ = g.noise(p, s * 3.0, 2.0, 0.6)
        h = g.lerp(h, fib, L["fibers"] * 0.4)
        return {"fac": h, "height": h}
    # plain / twill: which thread is on top in each crossing
    iu, iv = g.floor(u), g.floor(v)
    if kind == "twill":
        over = g.math("LESS_THAN", g.frac(g.div(g.add(iu, iv), 4.0)), 0.5)
    else:
        over = g.math("LESS_THAN", g.frac(g.div(g.add(iu, iv), 2.0)), 0.5)
    warp = g.sqrt(g.abs(g.sin(g.mul(v, math.pi))))  # threads along u
    weft = g.sqrt(g.abs(g.sin(g.mul(u, math.pi))))  # threads along v
    h = g.lerp(weft, warp, over)
    fib, _ = g.noise(p, s * 4.0, 2.0, 0.6)
    h = g.lerp(h, g.mul(h, fib), L["fibers"])
    fac = g.lerp(g.mul(over, 0.8), fib, L["fibers"] * 0.3)
    return {"fac": fac, "height": h}


def rings(g, p, L, ctx):
    s = L["scale"]
    q = g.vscale(p, s)
    out = []
    for shift in ((0.0, 0.0, 0.0), (0.5, 0.5, 0.5)):
        qs = g.vmath("ADD", q, shift)
        c = g.vmath("ADD", g.vmath("FLOOR", qs), (0.5, 0.5, 0.5))
        d = g.vmath("DISTANCE", qs, c)
        out.append(g.smooth(L["thickness"], 0.0, g.abs(g.sub(d, L["radius"]))))
    h = g.mx(out[0], g.mul(out[1], 0.85))
    gap = g.smooth(0.35, 0.0, h)
    return {"fac": h, "height": h, "gap": gap}


def waves(g, p, L, ctx):
    dx, dy, dz = L["direction"]
    norm = math.sqrt(dx * dx + dy * dy + dz * dz) or 1.0
    t = g.div(g.vmath("DOT_PRODUCT", p, (dx / norm, dy / norm, dz / norm)), L["period"])
    if L["wobble"] > 0:
        n, _ = g.noise(p, 1.0, 2.0, 0.5)
        t = g.madd(n, L["wobble"], t)
    prof = L["profile"]
    if prof == "saw":
        h = g.frac(t)
    else:
        h = g.madd(g.sin(g.mul(t, 2.0 * math.pi)), 0.5, 0.5)
        if prof == "square":
            h = g.smooth(0.35, 0.65, h)
    if L["line"] > 0:
        # Stripes of duty `line`: where the sine is in its top `line` fraction of phase.
        th = math.cos(math.pi * L["line"]) * 0.5 + 0.5
        mask = g.smooth(th - 0.01, th + 0.01, h)
        return {"fac": h, "height": mask, "mask": mask}
    return {"fac": h, "height": h}


def spots(g, p, L, ctx):
    f1 = g.voronoi(p, L["scale"], "F1", L["randomness"])
    cell = g.sep(f1["Color"])[0]
    r = g.mul(L["size"], g.sub(1.0, g.mul(cell, L["size_noise"])))
    d = g.div(f1["Distance"], r)
    mask = g.smooth(1.0, 1.0 - L["softness"], d)
    h = g.sqrt(g.clamp01(g.sub(1.0, g.mul(d, d))))
    return {"fac": cell, "height": h, "mask": mask}


def scratches(g, p, L, ctx):
    dx, dy, dz = L["direction"]
    norm = math.sqrt(dx * dx + dy * dy + dz * dz) or 1.0
    dvec = (dx / norm, dy / norm, dz / norm)
    k = L["stretch"]
    along = g.vmath("DOT_PRODUCT", p, dvec)
    q = g.vmath("SUBTRACT", g.vscale(p, k), g.vscale(dvec, g.mul(along, k - 1.0)))
    n, _ = g.noise(q, L["scale"], 2.0, 0.5)
    ridge = g.sub(1.0, g.abs(g.madd(n, 2.0, -1.0)))
    mask = g.smooth(1.0 - L["width"], 1.0 - 0.3 * L["width"], ridge)
    return {"fac": n, "height": mask, "mask": mask}


def cracks(g, p, L, ctx):
    q = p
    if L["distortion"] > 0:
        _, c = g.noise(p, L["scale"] * 2.0, 3.0, 0.6)
        q = g.vmath("ADD", p, g.vscale(g.vmath("SUBTRACT", c, (0.5, 0.5, 0.5)),
                                        L["distortion"] / L["scale"]))
    edge = g.voronoi(q, L["scale"], "DISTANCE_TO_EDGE", 1.0)["Distance"]
    mask = g.smooth(L["width"], 0.0, edge)
    return {"fac": g.clamp01(edge), "height": mask, "mask": mask}


def image(g, p, L, ctx):
    import bpy

    img = bpy.data.images.load(L["path"], check_existing=True)
    n = g.node("ShaderNodeTexImage", projection="BOX", projection_blend=L["blend"])
    n.image = img
    g.set(n.inputs["Vector"], g.vscale(p, 1.0 / L["tile"]))
    col = n.outputs["Color"]
    lum = g.luminance(col)
    return {"fac": lum, "height": lum, "color": col}


def _socket(coll, key):
    """A socket by index (`"1"`), name (first match) or identifier (`Value_001`)."""
    if key.isdigit():
        i = int(key)
        return coll[i] if i < len(coll) else None
    for s in coll:
        if s.name == key and s.enabled:
            return s
    for s in coll:
        if s.identifier == key:
            return s
    return None


def graph(g, p, L, ctx):
    nodes = {}
    for name, spec in L["nodes"].items():
        n = g.node(spec["type"])
        for k, v in (spec.get("props") or {}).items():
            setattr(n, k, v)
        nodes[name] = n
    for name, spec in L["nodes"].items():
        for k, v in (spec.get("inputs") or {}).items():
            sock = _socket(nodes[name].inputs, k)
            if sock is None:
                raise ValueError("graph node `%s` has no input `%s`" % (name, k))
            g.set(sock, v)
    sources = {"coord": p, "random": ctx["random"], "normal": ctx["normal"]}
    out = {}
    for src, dst in L["links"]:
        if src in sources:
            s = sources[src]
        else:
            node, sock = src.split(".", 1)
            s = _socket(nodes[node].outputs, sock)
            if s is None:
                raise ValueError("graph node `%s` has no output `%s`" % (node, sock))
        if dst.startswith("out."):
            out[dst[4:]] = s
        else:
            node, sock = dst.split(".", 1)
            d = _socket(nodes[node].inputs, sock)
            if d is None:
                raise ValueError("graph node `%s` has no input `%s`" % (node, sock))
            g.set(d, s)
    out.setdefault("fac", 0.0)
    return out


BLOCKS = {
    "solid": solid,
    "noise": noise,
    "cells": cells,
    "bricks": bricks,
    "wood": wood,
    "veins": veins,
    "weave": weave,
    "rings": rings,
    "waves": waves,
    "spots": spots,
    "scratches": scratches,
    "cracks": cracks,
    "image": image,
    "graph": graph,
}
