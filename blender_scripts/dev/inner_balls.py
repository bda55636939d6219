"""Balls enclosed by each shape's mesh, for the Rust pre-accept (issue 40; dev).

    blender -b --factory-startup --python-exit-code 1 \
        --python blender_scripts/dev/inner_balls.py -- fit OUT.json
    blender -b --factory-startup --python-exit-code 1 \
        --python blender_scripts/dev/inner_balls.py -- check TABLE.json REPORT.json
    .venv-bpy/bin/python blender_scripts/dev/inner_balls.py check TABLE.json REPORT.json

A ball is *enclosed* by a shape when every ray that leaves a point of the ball's surface
outwards (any direction with a non-negative component along the outward normal there) meets
the shape's evaluated mesh (the bridge's `shapes.new_object`: the normalised mesh under its
level-1 subdivision, undisplaced, as the visibility render sees it). Then a camera ray that
enters the ball has met the object at or before that depth, whatever the mesh's holes
(the monkey's, the teapot's), which is what `clevrtex_scene::visibility` needs of its inner
bodies.

`fit` grows balls from a grid of enclosed points (radius: distance to the mesh), picks them
greedily by the grid points they add, shrinks each until `check`'s test passes with a margin,
and writes {shape: [[x, y, z, r], ...]} (normalised units). `check` tests the tables of
`crates/scene/src/visibility.rs` (dumped by the test `visibility_bound::` as {shape: {"balls":
[[x, y, z, r], ...], "box": [[lo, hi], [lo, hi], [lo, hi]], "radial": r}}): each ball enclosed,
and every vertex of the evaluated mesh inside the box and within `radial` of the vertical
axis. It writes, per shape, what fails (a ball with the ray that escapes, a vertex outside);
exit code 1 when something fails.
"""

import json
import math
import os
import sys

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, os.path.dirname(HERE))

import bpy  # noqa: E402
from mathutils import Vector  # noqa: E402
from mathutils.bvhtree import BVHTree  # noqa: E402

import shapes  # noqa: E402


def fibonacci(n):
    """n unit vectors spread over the sphere."""
    out = []
    golden = math.pi * (3.0 - math.sqrt(5.0))
    for i in range(n):
        z = 1.0 - 2.0 * (i + 0.5) / n
        r = math.sqrt(max(0.0, 1.0 - z * z))
        out.append(Vector((r * math.cos(golden * i), r * math.sin(golden * i), z)))
    return out


def tree(shape):
    """A BVH of the shape's evaluated mesh (subdivision applied), in normalised units."""
    obj = shapes.new_object(shape, "probe_" + shape, bpy.context.scene.collection)
    deps = bpy.context.evaluated_depsgraph_get()
    ev = obj.evaluated_get(deps)
    return BVHTree.FromObject(ev, deps)


def closed(shape):
    """Whether the shape's evaluated mesh is closed (every edge between exactly two faces)."""
    import bmesh

    ev = bpy.data.objects["probe_" + shape].evaluated_get(bpy.context.evaluated_depsgraph_get())
    bm = bmesh.new()
    bm.from_mesh(ev.to_mesh())
    ok = all(len(e.link_faces) == 2 for e in bm.edges)
    bm.free()
    return ok


def inside_closed(bvh, centre, radius):
    """A ball inside a closed mesh: its centre inside (odd crossings along a ray) and no
    surface point nearer than its radius. Then every ray from it meets the mesh."""
    near = bvh.find_nearest(centre)
    if near[0] is None or near[3] < radius:
        return False
    d = Vector((0.3, 0.2, 0.93)).normalized()
    p, crossings = centre.copy(), 0
    while True:
        hit = bvh.ray_cast(p, d, 10.0)
        if hit[0] is None:
            break
        crossings += 1
        p = hit[0] + d * 1e-5
    return crossings % 2 == 1


def escapes(bvh, centre, radius, points=160, dirs=160):
    """The first (point, direction) whose outward ray misses the mesh, or None."""
    sphere_dirs = fibonacci(dirs)
    for n in fibonacci(points):
        p = centre + n * radius
        for d in sphere_dirs:
            if d.dot(n) < 0.0:
                continue
            # Start just outside the surface point: a ray grazing the mesh at its origin must
            # not count as a hit.
            hit = bvh.ray_cast(p + d * 1e-5, d, 10.0)
            if hit[0] is None:
                return (list(p), list(d))
    return None


def enclosed(shape, bvh, centre, radius):
    """No ray leaves the ball outwards without meeting the mesh: exact for a closed mesh;
    sampled densely (400 surface points x 400 directions) for an open one (the monkey's eye
    holes, the teapot's seams), whose balls are fitted with a further margin."""
    if closed(shape):
        return inside_closed(bvh, centre, radius)
    return escapes(bvh, centre, radius, 400, 400) is None


def fit(shape, bvh, step=0.1, keep=12, margin=0.97):
    grid = []
    k = int(round(2.0 / step))
    probe = fibonacci(26)
    for i in range(k + 1):
        for j in range(k + 1):
            for m in range(k + 1):
                p = Vector((-1.0 + i * step, -1.0 + j * step, -1.0 + m * step))
                if all(bvh.ray_cast(p, d, 10.0)[0] is not None for d in probe):
                    near = bvh.find_nearest(p)
                    if near[0] is not None and near[3] > step * 0.5:
                        grid.append((p, near[3]))
    import numpy as np

    pts = np.array([list(p) for p, _ in grid])
    rad = np.array([r for _, r in grid])
    dist = np.linalg.norm(pts[:, None, :] - pts[None, :, :], axis=2)
    reach = dist <= rad[:, None]
    covered = np.zeros(len(grid), dtype=bool)
    chosen = []
    while len(chosen) < keep:
        gain = reach[:, ~covered].sum(axis=1)
        i = int(gain.argmax())
        if gain[i] < 3:
            break
        c, r = grid[i][0], grid[i][1] * margin
        if not closed(shape):
            r *= 0.9
        while r > 0.02 and not enclosed(shape, bvh, c, r):
            r *= 0.95
        if r <= 0.02:
            covered |= reach[i]
            continue
        chosen.append([round(c.x, 3), round(c.y, 3), round(c.z, 3), math.floor(r * 1000) / 1000])
        # What the candidate would have added counts as taken either way, so it is not
        # picked again for the sliver its shrinking gave up.
        covered |= reach[i]
    return chosen


def main(argv):
    if not argv or argv[0] not in ("fit", "check"):
        raise SystemExit(__doc__)
    out = {}
    failed = False
    if argv[0] == "fit":
        for shape in shapes.SHAPES:
            out[shape] = fit(shape, tree(shape))
            print(shape, len(out[shape]), out[shape], flush=True)
        path = argv[1]
    else:
        with open(argv[1]) as f:
            table = json.load(f)
        for shape, spec in table.items():
            bvh = tree(shape)
            bad = []
            ev = bpy.data.objects["probe_" + shape].evaluated_get(
                bpy.context.evaluated_depsgraph_get())
            for v in ev.to_mesh().vertices:
                co = v.co
                inside = all(lo <= co[k] <= hi for k, (lo, hi) in enumerate(spec["box"]))
                if not inside or math.hypot(co.x, co.y) > spec["radial"]:
                    bad.append({"vertex": list(co)})
                    break
            for x, y, z, r in spec["balls"]:
                if not enclosed(shape, bvh, Vector((x, y, z)), r):
                    bad.append({"ball": [x, y, z, r], "closed": closed(shape)})
            out[shape] = bad
            failed = failed or bool(bad)
        path = argv[2]
    with open(path, "w") as f:
        json.dump(out, f, indent=1)
    if failed:
        sys.exit(1)


if __name__ == "__main__":
    args = sys.argv[sys.argv.index("--") + 1:] if "--" in sys.argv else sys.argv[1:]
    main(args)
