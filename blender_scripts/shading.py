"""Materials on a built scene: node-tree templates per worker (assign_materials), adaptive
subdivision where a material displaces, the shapes' subdivision modifier where a material
may read the unsubdivided mesh (reads_unsubdivided)."""

import json
import time

import bpy

import compat
import materials
import shapes


def material_displaces(mat):
    """True if Cycles will displace geometry with `mat` (true displacement, not bump)."""
    if mat is None or not mat.use_nodes:
        return False
    if compat.displacement_method(mat) not in ("DISPLACEMENT", "BOTH"):
        return False
    for node in mat.node_tree.nodes:
        if node.type == "OUTPUT_MATERIAL" and node.is_active_output:
            sock = node.inputs.get("Displacement")
            return sock is not None and sock.is_linked
    return False


def reads_unsubdivided(mat):
    """Whether `mat` may read something of its object's mesh that the shapes' subdivided copy
    (shapes.new_object) gives otherwise than the shape's mesh with its subdivision modifier:
    Generated coordinates, which come from the unsubdivided mesh (its texture space, and
    positions interpolated linearly, not to the limit surface). Cycles reads them from a
    Texture Coordinate node's Generated output, a texture node's unlinked Vector, a tangent
    left unlinked on an anisotropic BSDF, a Tangent node, and may from a mesh attribute,
    a script or a point density: each of these counts, in the material's tree and in every
    node group in it. Positions, normals, UVs and Object coordinates are the same on both
    (the catalogue's materials read Object coordinates). True where unsure."""
    if mat is None or not mat.use_nodes or mat.node_tree is None:
        return False
    return _tree_reads_unsubdivided(mat.node_tree, set())


def _tree_reads_unsubdivided(tree, seen):
    if tree.name in seen:
        return False
    seen.add(tree.name)
    for node in tree.nodes:
        kind = node.type
        if kind == "GROUP":
            if node.node_tree is not None and _tree_reads_unsubdivided(node.node_tree, seen):
                return True
            continue
        if kind == "TEX_COORD":
            if node.outputs["Generated"].is_linked:
                return True
            continue
        if kind in ("TANGENT", "SCRIPT", "TEX_POINTDENSITY", "CUSTOM"):
            return True
        if kind == "ATTRIBUTE" and node.attribute_type != "OBJECT":
            return True
        # Unused where disabled (white noise in 1D; 4.x's `get` does not find it then).
        vector = next((i for i in node.inputs if i.identifier == "Vector"), None)
        if kind.startswith("TEX_") and (vector is None or (
                getattr(vector, "enabled", True) and not vector.is_linked)):
            return True
        tangent = node.inputs.get("Tangent")
        if tangent is not None and not tangent.is_linked:
            amount = node.inputs.get("Anisotropic") or node.inputs.get("Anisotropy")
            if amount is None or amount.is_linked or amount.default_value != 0.0:
                return True
    return False


def _set_adaptive(obj, enabled, simple):
    """Adaptive subdivision on `obj` (needs a subdivision modifier last in the stack)."""
    mod = obj.modifiers.get("subdivision")
    if enabled and mod is None:
        mod = obj.modifiers.new("subdivision", "SUBSURF")
        mod.subdivision_type = "SIMPLE" if simple else "CATMULL_CLARK"
        mod.levels = 0
        mod.render_levels = 0
    compat.set_adaptive_subdivision(obj, mod, enabled)
    if not enabled and simple and mod is not None:
        obj.modifiers.remove(mod)


# The material templates of this worker, kept across scenes (a fake user keeps them through
# builder.clear()): materials.shared_key -> (material name, materials.Values). Bounded by the
# catalogue: one per material, context and set of optional values used.
_TEMPLATES = {}


def _template(key, build):
    """The template of `key`, built by build() -> (material, Values) the first time (or again
    after a factory reset removed it)."""
    entry = _TEMPLATES.get(key)
    if entry is not None:
        mat = bpy.data.materials.get(entry[0])
        if mat is not None and mat.use_fake_user:
            return mat, entry[1]
    mat, values = build()
    mat.use_fake_user = True
    _TEMPLATES[key] = (mat.name, values)
    return mat, values


def assign_materials(built, catalogue, build_material, displacement):
    """Assign every material the scene uses: a copy of its template (built the first time a
    scene of this worker uses it, materials.shared_key) with the instance's values set, or,
    where they cannot be set on a copy, a tree built for the instance."""
    # The albedo pass's AOV output only when that pass is requested (the same in the
    # visibility and the final context, so it never causes a rebuild of its own).
    context = {"displacement": bool(displacement),
               "albedo": "albedo" in built.spec.get("passes", [])}
    if built.material_context == context:
        return 0.0
    t0 = time.perf_counter()
    old = set(m.name for m in bpy.data.materials if not m.use_fake_user)
    made = {}

    def get(inst):
        name = inst["name"]
        if catalogue is not None and name not in catalogue:
            raise KeyError("material `%s` is not in the catalogue" % name)
        recipe = catalogue[name] if catalogue is not None else {}
        key = json.dumps(inst, sort_keys=True)
        if key in made:
            return made[key]
        shared = materials.shared_key(name, recipe, inst, context)
        if shared is None:
            made[key] = build_material(name, recipe, dict(inst), dict(context))
            return made[key]

        def build():
            values = materials.Values(dict(inst))
            return build_material(name, recipe, dict(inst), dict(context), values), values

        template, values = _template(shared, build)
        mat = template.copy()
        mat.use_fake_user = False
        values.apply(mat, inst)
        made[key] = mat
        return mat

    pairs = [(built.backdrop, built.spec["backdrop"]["material"], None)]
    pairs += [(o, s["material"], s["shape"]) for o, s in zip(built.objects, built.spec["objects"])]
    reads = {}
    for obj, inst, shape in pairs:
        mat = get(inst)
        displaces = displacement and material_displaces(mat)
        if shape is not None:
            # The shape's mesh and its subdivision modifier where the material displaces it
            # (adaptive subdivision) or may read what the object's subdivided copy changes;
            # elsewhere that copy, the same geometry and pixels without the modifier
            # evaluated again (shapes.make_final).
            if mat.name not in reads:
                reads[mat.name] = reads_unsubdivided(mat)
            if displaces or reads[mat.name]:
                shapes.make_final(obj, shape)
        obj.material_slots[0].material = mat
        _set_adaptive(obj, displaces, shape is None)
    keep = set(m.name for m in made.values())
    for name in old:
        mat = bpy.data.materials.get(name)
        if mat is not None and name not in keep:
            bpy.data.materials.remove(mat)
    built.material_context = context
    return time.perf_counter() - t0


