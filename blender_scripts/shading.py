"""Materials on a built scene: node-tree templates per worker (assign_materials), adaptive
subdivision where a material displaces."""

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

    # The objects as the final render renders them: the shape's mesh and its subdivision
    # modifier (the visibility pass renders a copy of the subdivided mesh instead).
    for obj, ospec in zip(built.objects, built.spec["objects"]):
        shapes.make_final(obj, ospec["shape"])
    pairs = [(built.backdrop, built.spec["backdrop"]["material"], True)]
    pairs += [(o, s["material"], False) for o, s in zip(built.objects, built.spec["objects"])]
    for obj, inst, simple in pairs:
        mat = get(inst)
        obj.material_slots[0].material = mat
        displaces = displacement and material_displaces(mat)
        _set_adaptive(obj, displaces, simple)
    keep = set(m.name for m in made.values())
    for name in old:
        mat = bpy.data.materials.get(name)
        if mat is not None and name not in keep:
            bpy.data.materials.remove(mat)
    built.material_context = context
    return time.perf_counter() - t0


