"""Object meshes: the eight shapes, normalised to [-1, 1]^3, built once per worker.

Every shape is scaled uniformly so its largest extent is 2, centred in x and y, and shifted
so it rests on z = -1 (the sampler puts the origin at z = scale, so the object sits on the
floor). The one exception is the monkey, which the reference places at z in [-0.97, 0.48]
(the public generator's `clevrtex-gen/data/shapes/Suzanne.blend`, karazijal/clevrtex-generation).
Hard edges are bevelled before the level-1 subdivision modifier that every
shape carries, so cubes stay cubes and cylinders keep flat caps, as in CLEVR's smooth shapes.

Meshes are cached for the worker's life and shared by every object of that shape (materials
are linked to the object, not the mesh), so a rebuild never re-tessellates them.

Each object is a copy of its shape's level-1 subdivision, made once per worker by Blender's
own modifier (`subdivide`), with no modifier of its own: the same geometry, positions,
normals and UVs as the shape's mesh with the modifier, which Blender evaluated again for
every object of every render (~0.07 s an object on this project's machines, most of a 32x24
image's time: docs/notes/performance.md, "The fixed cost of a small image"). An object gets
the shape's mesh and the modifier back (`make_final`) where its material in the final render
displaces it (adaptive subdivision subdivides the shape's mesh) or may read its Generated
coordinates, which come from the unsubdivided mesh (shading.reads_unsubdivided).
"""

import math

import bmesh
import bpy
from mathutils import Matrix, Vector

import compat

SHAPES = ("cube", "sphere", "cylinder", "monkey", "cone", "torus", "icosahedron", "teapot")

# Subdivision level of the modifier every shape carries (as the public generator's shape files,
# karazijal/clevrtex-generation `clevrtex-gen/data/shapes/`).
SUBDIVISION_LEVEL = 1
# Bevel width (in the normalised [-1, 1] frame) of the edges that would otherwise be rounded
# away by the subdivision.
BEVEL_WIDTH = 0.08

MESH_PREFIX = "clevrtex_shape_"
SUBDIVIDED_PREFIX = "clevrtex_subdivided_"

_cache = {}
_subdivided = {}


def _bevel(bm, edges, width=BEVEL_WIDTH, segments=2):
    bmesh.ops.bevel(
        bm,
        geom=list(edges),
        offset=width,
        offset_type="OFFSET",
        segments=segments,
        profile=0.5,
        affect="EDGES",
        clamp_overlap=True,
    )


def _sharp_edges(bm, angle_deg=40.0):
    limit = math.radians(angle_deg)
    return [e for e in bm.edges if e.is_manifold and e.calc_face_angle(0.0) > limit]


def _make_cube(bm):
    bmesh.ops.create_cube(bm, size=2.0, calc_uvs=True)
    _bevel(bm, bm.edges[:])


def _make_sphere(bm):
    bmesh.ops.create_uvsphere(bm, u_segments=32, v_segments=16, radius=1.0, calc_uvs=True)


def _make_cylinder(bm):
    bmesh.ops.create_cone(
        bm, cap_ends=True, cap_tris=False, segments=32, radius1=1.0, radius2=1.0, depth=2.0,
        calc_uvs=True,
    )
    _bevel(bm, _sharp_edges(bm))


def _make_cone(bm):
    bmesh.ops.create_cone(
        bm, cap_ends=True, cap_tris=False, segments=32, radius1=1.0, radius2=0.0, depth=2.0,
        calc_uvs=True,
    )
    # Only the base rim: the apex is a pole, not an edge.
    rim = [e for e in _sharp_edges(bm) if all(v.co.z < 0.0 for v in e.verts)]
    _bevel(bm, rim)


def _make_icosahedron(bm):
    bmesh.ops.create_icosphere(bm, subdivisions=1, radius=1.0, calc_uvs=True)
    # A coplanar inset ring holds each facet flat under the subdivision (a bevel does not
    # on triangles: the icosahedron came out as a blob).
    bmesh.ops.inset_individual(bm, faces=bm.faces[:], thickness=0.06, use_even_offset=True)


def _make_monkey(bm):
    bmesh.ops.create_monkey(bm, calc_uvs=True)


def _make_torus(bm, major_segments=48, minor_segments=16, major=0.75, minor=0.25):
    uv_layer = bm.loops.layers.uv.verify()
    grid = []
    for i in range(major_segments):
        u = 2.0 * math.pi * i / major_segments
        row = []
        for j in range(minor_segments):
            v = 2.0 * math.pi * j / minor_segments
            r = major + minor * math.cos(v)
            row.append(bm.verts.new((r * math.cos(u), r * math.sin(u), minor * math.sin(v))))
        grid.append(row)
    for i in range(major_segments):
        for j in range(minor_segments):
            i1, j1 = (i + 1) % major_segments, (j + 1) % minor_segments
            face = bm.faces.new((grid[i][j], grid[i1][j], grid[i1][j1], grid[i][j1]))
            corners = ((i, j), (i + 1, j), (i + 1, j + 1), (i, j + 1))
            for loop, (ci, cj) in zip(face.loops, corners):
                loop[uv_layer].uv = (ci / major_segments, cj / minor_segments)


def _box_uvs(bm):
    """Box-projected UVs for meshes that come without any (the teapot)."""
    uv_layer = bm.loops.layers.uv.verify()
    for face in bm.faces:
        n = face.normal
        axis = max(range(3), key=lambda k: abs(n[k]))
        a, b = [k for k in range(3) if k != axis]
        for loop in face.loops:
            co = loop.vert.co
            loop[uv_layer].uv = (0.5 + 0.5 * co[a], 0.5 + 0.5 * co[b])


def _make_teapot(bm):
    verts, faces = compat.teapot_mesh()
    bverts = [bm.verts.new(co) for co in verts]
    for face in faces:
        # Bezier patches collapse to points at the lid knob and the base: drop repeated
        # corners, and faces left with fewer than three.
        idx = []
        for k in face:
            if k not in idx:
                idx.append(k)
        if len(idx) >= 3:
            try:
                bm.faces.new([bverts[k] for k in idx])
            except ValueError:  # same face twice where patches meet
                pass
    bmesh.ops.remove_doubles(bm, verts=bm.verts[:], dist=1e-4)
    bmesh.ops.recalc_face_normals(bm, faces=bm.faces[:])


_BUILDERS = {
    "cube": _make_cube,
    "sphere": _make_sphere,
    "cylinder": _make_cylinder,
    "monkey": _make_monkey,
    "cone": _make_cone,
    "torus": _make_torus,
    "icosahedron": _make_icosahedron,
    "teapot": _make_teapot,
}

# Smooth shading would round the facets off visually even where the geometry is flat.
_FLAT_SHADED = ("icosahedron",)

# z range of the normalised mesh: (bottom, top or None for "whatever the aspect gives").
_Z_BOTTOM = {"monkey": -0.97}


def _normalise(bm, shape):
    lo = Vector([min(v.co[k] for v in bm.verts) for k in range(3)])
    hi = Vector([max(v.co[k] for v in bm.verts) for k in range(3)])
    scale = 2.0 / max(hi - lo)
    centre = (lo + hi) / 2.0
    bottom = _Z_BOTTOM.get(shape, -1.0)
    shift = Vector((-centre.x * scale, -centre.y * scale, bottom - lo.z * scale))
    bmesh.ops.transform(bm, matrix=Matrix.Translation(shift) @ Matrix.Scale(scale, 4),
                        verts=bm.verts[:])


def mesh(shape):
    """The cached, normalised mesh of `shape`."""
    if shape not in _BUILDERS:
        raise ValueError("unknown shape `%s`; known: %s" % (shape, ", ".join(SHAPES)))
    cached = _cache.get(shape)
    if cached is not None:
        try:
            cached.name  # raises ReferenceError if something removed it
            return cached
        except ReferenceError:
            pass
    bm = bmesh.new()
    _BUILDERS[shape](bm)
    if shape == "teapot":
        _normalise(bm, shape)
        _box_uvs(bm)
    else:
        _normalise(bm, shape)
    me = bpy.data.meshes.new(MESH_PREFIX + shape)
    bm.to_mesh(me)
    bm.free()
    if shape not in _FLAT_SHADED:
        compat.shade_smooth(me)
    # One slot; each object links its own material to it (link = 'OBJECT').
    me.materials.append(None)
    me.use_fake_user = True
    _cache[shape] = me
    return me


def _alive(cache):
    """The meshes of `cache` still alive; a removed one (a factory reset removes them all) is
    dropped from it, to be built again."""
    alive = []
    for shape, me in list(cache.items()):
        try:
            me.name  # raises ReferenceError if something removed it
        except ReferenceError:
            del cache[shape]
            continue
        alive.append(me)
    return alive


def cached_meshes():
    """The cached meshes still alive (the shapes' and their subdivisions). A factory reset
    (the `material` request's scenes start from one) removes them: they are dropped here and
    `mesh` and `subdivide` build them again."""
    return _alive(_cache) + _alive(_subdivided)


def _new_subdivision_modifier(obj):
    mod = obj.modifiers.new("subdivision", "SUBSURF")
    mod.levels = SUBDIVISION_LEVEL
    mod.render_levels = SUBDIVISION_LEVEL
    return mod


def subdivide(shapes):
    """Make the level-1 subdivision of each of `shapes` not made yet: the mesh Blender's
    modifier makes of the shape's mesh (what an object of the final render carries), taken
    from an evaluated temporary object. Call it with no other object in the scene (builder.build
    does, right after clear()): the evaluation covers every object of the view layer."""
    _alive(_subdivided)
    todo = sorted(set(shapes) - set(_subdivided))
    if not todo:
        return
    collection = bpy.context.scene.collection
    temporary = []
    for shape in todo:
        obj = bpy.data.objects.new("clevrtex_subdivide_" + shape, mesh(shape))
        collection.objects.link(obj)
        _new_subdivision_modifier(obj)
        temporary.append((shape, obj))
    try:
        depsgraph = bpy.context.evaluated_depsgraph_get()
        for shape, obj in temporary:
            me = bpy.data.meshes.new_from_object(obj.evaluated_get(depsgraph),
                                                 depsgraph=depsgraph)
            me.name = SUBDIVIDED_PREFIX + shape
            me.use_fake_user = True
            # Level 1 makes a quad of every corner: anything else means the modifier did not
            # run on the CPU (e.g. left to a GPU for drawing), and the mask would change.
            if len(me.polygons) != len(obj.data.loops) or len(me.loops) != 4 * len(me.polygons):
                bpy.data.meshes.remove(me)
                raise RuntimeError("the subdivision of `%s` was not made (%d faces from %d "
                                   "corners)" % (shape, len(me.polygons), len(obj.data.loops)))
            _subdivided[shape] = me
    finally:
        for _, obj in temporary:
            bpy.data.objects.remove(obj, do_unlink=True)


def new_object(shape, name, collection):
    """A new object of `shape`, linked into `collection`: its own copy of the shape's
    subdivision (`subdivide` first), no modifier; `make_final` gives it the shape's mesh and
    modifier. A copy for each object: objects that share a mesh are instances to Cycles,
    traced with the object's transform applied to the ray instead of to the vertices.
    A shape not subdivided yet is subdivided here (slower with other objects in the scene:
    the evaluation covers them too)."""
    if shape not in _subdivided:
        subdivide([shape])
    obj = bpy.data.objects.new(name, _subdivided[shape].copy())
    collection.objects.link(obj)
    obj.material_slots[0].link = "OBJECT"
    return obj


def make_final(obj, shape):
    """`obj` (of `new_object`) with the shape's mesh and its subdivision modifier, for a
    material that displaces it or may read its unsubdivided mesh; its copy is removed.
    Nothing happens the second time."""
    if obj.modifiers.get("subdivision") is not None:
        return
    copy = obj.data
    obj.data = mesh(shape)
    _new_subdivision_modifier(obj)
    obj.material_slots[0].link = "OBJECT"
    if copy.users == 0:
        bpy.data.meshes.remove(copy)
