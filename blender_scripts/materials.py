"""Builds catalogue materials as Cycles node trees.

    build_material(name, recipe, instance, context) -> bpy.types.Material

- name: catalogue name;
- recipe: the material's entry of materials.json, resolved by clevrtex-materials (every
  default filled, colours linear); see docs/material-recipes.md;
- instance: the scene file's MaterialInstance as a dict (random, color, displacement, scale);
- context: {"displacement": bool, "albedo": bool} -- displacement False for the cheap
  visibility pass, where no displacement may be set up; albedo True when the albedo pass is
  requested: the material then writes its base colour (metals: their colour) to the colour
  AOV `BaseCol` (passes.PASSES), and otherwise has no such node.

Coordinates: Object coordinates times the object's own scale (read by an Attribute node, so
one material serves objects of any size), i.e. world units in the object's frame. A large
cube therefore shows more bricks, not bigger ones; the pattern moves and turns with the
object, and 3D patterns have no UV seams. Then times recipe `scale` times instance `scale`,
plus an offset drawn from instance `random`.

A recipe of kind `pbr` is a folder of PBR texture maps (Poly Haven or ambientCG names,
checked by clevrtex-materials `pbr.rs`): the maps are projected from the three axes of the
same coordinates (one image repeat per recipe `tile` world units) and blended by the object
normal, normal maps perturb the normal in those projections' tangent frames (DirectX maps:
green flipped), the displacement map is used only where the scene displaces.

A recipe of kind `layers` is a stack of blocks (material_blocks.BLOCKS) composited into
colour, roughness, metallic and height; height drives a Bump node and, only when the recipe
displaces, the instance has a displacement strength and the context allows it, a
Displacement node. A recipe of kind `blend` uses a user node group from a .blend file.
"""

import os

import bpy

import compat
import material_blocks
from material_nodes import Graph

# Offsets per unit of `random` and per unit of cell id: mostly along x so that wood rings
# around the x axis keep their curvature, large enough to decorrelate every noise.
RANDOM_OFFSET = (73.1, 0.61, 0.37)
CELL_OFFSET = (31.7, 0.43, 0.29)
# The colour AOV of the albedo pass (passes.PASSES["albedo"]).
ALBEDO_AOV = "BaseCol"


class Values:
    """A material's per-object values (coordinate scale and offset, tint, displacement
    strength, a user group's driven inputs): `put(socket, fn)` sets the constant
    fn(instance) on an input socket and records where it went, so a tree built once (the
    template, kept per worker: shading.assign_materials) serves another instance as a copy
    with these inputs set again (`apply(material, instance)`). A copy is the tree a build for
    that instance makes, constant for constant, so its renders are bit-identical."""

    def __init__(self, instance):
        self.instance = instance
        self.sites = []  # (node name, input index, fn)

    def put(self, socket, fn):
        node = socket.node
        index = next(i for i, s in enumerate(node.inputs)
                     if s.as_pointer() == socket.as_pointer())
        self.sites.append((node.name, index, fn))
        socket.default_value = fn(self.instance)

    def apply(self, mat, instance):
        """Set `mat` (a copy of the template) for `instance`."""
        nodes = mat.node_tree.nodes
        for name, index, fn in self.sites:
            nodes[name].inputs[index].default_value = fn(instance)


def shared_key(name, recipe, instance, context):
    """What a material's tree depends on besides its per-object values (Values): the name,
    the context, and which optional values the instance has; None where a value does not
    land on one socket as itself (the tree is built for the instance)."""
    recipe = recipe or {}
    if instance.get("color") is not None and recipe.get("tint", "multiply") == "replace":
        return None  # the colour feeds several sockets, some through compat's conversions
    for layer in recipe.get("layers") or []:
        # A `graph` layer may feed `random` into Python-folded arithmetic.
        if layer.get("block") == "graph" and any(
                src == "random" for src, _dst in layer.get("links") or []):
            return None
    return (name, bool(context.get("displacement", True)), bool(context.get("albedo", False)),
            instance.get("color") is not None, instance.get("scale") is not None,
            (instance.get("displacement") or 0.0) > 0.0)


def build_material(name, recipe, instance, context, values=None):
    """The material for `instance`; `values` (a Values of `instance`) records where its
    per-object values went."""
    vals = values if values is not None else Values(instance)
    kind = recipe.get("kind", "layers") if recipe else "layers"
    if not recipe:
        recipe = {"kind": "layers", "layers": [], "surface": {}}
    mat = bpy.data.materials.new(name)
    mat.use_nodes = True
    nt = mat.node_tree
    nt.nodes.clear()
    out = nt.nodes.new("ShaderNodeOutputMaterial")
    out.location = (1600, 0)
    displace = (
        bool(recipe.get("displaces"))
        and bool(context.get("displacement", True))
        and (instance.get("displacement") or 0.0) > 0.0
    )
    albedo = bool(context.get("albedo", False))
    if kind == "blend":
        _build_blend(nt, out, recipe, instance, displace, albedo, vals)
    elif kind == "pbr":
        displace = _build_pbr(nt, out, name, recipe, instance, displace, albedo, vals)
    else:
        displace = _build_layers(nt, out, recipe, instance, displace, albedo, vals)
    compat.set_displacement_method(mat, compat.true_displacement_method() if displace else "BUMP")
    return mat


def _coords(g, recipe, vals):
    tc = g.node("ShaderNodeTexCoord")
    attr = g.node("ShaderNodeAttribute", attribute_type="OBJECT", attribute_name="scale")
    p = g.vmath("MULTIPLY", tc.outputs["Object"], attr.outputs["Vector"])
    rscale = float(recipe.get("scale", 1.0))

    def k(i):
        k = rscale * float(i.get("scale") or 1.0)
        return (k, k, k)

    # One node: p * k + off.
    p = g.vmath("MULTIPLY_ADD", p, (1.0, 1.0, 1.0))
    vals.put(p.node.inputs[1], k)
    vals.put(p.node.inputs[2], lambda i: tuple(
        float(i.get("random") or 0.0) * o for o in RANDOM_OFFSET))
    return p, tc.outputs["Normal"]


def _principled(g, color, rough, metal, specular, albedo):
    """The Principled BSDF of a material (recipe or PBR folder) with its base colour, roughness,
    metallic and specular set, and, where the albedo pass is asked for, the albedo AOV fed the
    same base colour (the pass is the material's base colour)."""
    bsdf = g.node("ShaderNodeBsdfPrincipled")
    compat.setup_principled(bsdf)
    _set_bsdf(g, bsdf, "Base Color", compat.disney_diffuse(g, color, rough, metal))
    if albedo:
        aov = g.node("ShaderNodeOutputAOV")
        compat.set_aov_name(aov, ALBEDO_AOV)
        g.set(aov.inputs["Color"], color)
    _set_bsdf(g, bsdf, "Roughness", rough)
    _set_bsdf(g, bsdf, "Metallic", metal)
    _set_bsdf(g, bsdf, "Specular", specular)
    return bsdf


def _set_bsdf(g, bsdf, name, value):
    """Set a Principled BSDF input named as in Blender 3.x (`compat.principled_input`);
    skipped where this Blender has no such input."""
    socket = compat.principled_input(bsdf, name)
    if socket is not None:
        g.set(socket, compat.principled_value(name, value))


def _displace(g, nt, out, vals, height, relief):
    """True displacement of the material output `out` by `height` times `relief` (world units).
    Object space, so divided by the object's scale (read per object) to keep world units."""
    d = g.node("ShaderNodeDisplacement", space="OBJECT")
    g.set(d.inputs["Height"], height)
    g.set(d.inputs["Midlevel"], 0.5)
    vals.put(d.inputs["Scale"], lambda i: relief * float(i["displacement"]))
    nt.links.new(d.outputs["Displacement"], out.inputs["Displacement"])


def _build_layers(nt, out, recipe, instance, displace, albedo, vals):
    g = Graph(nt)
    p, normal = _coords(g, recipe, vals)
    ctx = {"normal": normal, "cell": None, "inside": None, "_normal_xyz": None}
    ctx["random"] = float(instance.get("random") or 0.0)

    class _LazyXYZ(dict):
        def __getitem__(self, i):
            if ctx["_normal_xyz"] is None:
                ctx["_normal_xyz"] = g.sep(normal)
            return ctx["_normal_xyz"][i]

    ctx["normal_xyz"] = _LazyXYZ()
    layers = recipe.get("layers") or []
    first = layers[0] if layers else {"gap_color": [0.5, 0.5, 0.5], "gap_roughness": 0.5}
    color = tuple(first.get("gap_color", [0.5, 0.5, 0.5]))
    rough = first.get("gap_roughness", 0.5)
    metal = 0.0
    height = None
    for L in layers:
        color, rough, metal, height = _layer(g, p, L, ctx, color, rough, metal, height)

    color = _tint(g, color, recipe.get("tint", "multiply"), instance.get("color"), vals)
    surf = recipe.get("surface") or {}
    bsdf = _principled(g, color, rough, metal, surf.get("specular", 0.5), albedo)
    if surf.get("sheen", 0.0) > 0:
        _set_bsdf(g, bsdf, "Sheen", surf["sheen"])
    if surf.get("coat", 0.0) > 0:
        _set_bsdf(g, bsdf, "Clearcoat", surf["coat"])
        _set_bsdf(g, bsdf, "Clearcoat Roughness", surf.get("coat_roughness", 0.05))
    if surf.get("subsurface", 0.0) > 0:
        _set_bsdf(g, bsdf, "Subsurface", surf["subsurface"])
        _set_bsdf(g, bsdf, "Subsurface Color", color)
        _set_bsdf(g, bsdf, "Subsurface Radius", (0.05, 0.03, 0.02))
    bump = surf.get("bump", 0.0)
    if height is not None and bump > 0 and hasattr(height, "node"):
        b = g.node("ShaderNodeBump")
        compat.setup_bump(b)
        g.set(b.inputs["Height"], height)
        g.set(b.inputs["Distance"], bump)
        _set_bsdf(g, bsdf, "Normal", b.outputs["Normal"])
    nt.links.new(compat.principled_output(nt, bsdf, color), out.inputs["Surface"])
    relief = surf.get("relief", 0.0)
    if displace and relief > 0 and height is not None and hasattr(height, "node"):
        _displace(g, nt, out, vals, height, relief)
        return True
    return False


def _layer(g, p, L, ctx, color, rough, metal, height):
    q = p
    if L.get("per_cell") and ctx["cell"] is not None:
        q = g.vmath("ADD", p, g.vmath("SCALE", CELL_OFFSET, scale=ctx["cell"]))
    res = material_blocks.BLOCKS[L["block"]](g, q, L, ctx)
    fac = res["fac"]
    if L["contrast"] != 1.0:
        fac = g.math("MULTIPLY_ADD", g.sub(fac, 0.5), L["contrast"], 0.5, clamp=True)

    var = L["variation"]
    v1 = v2 = None
    if var > 0:
        vs = L["variation_scale"]
        v1, _ = g.noise(q, 1.2 * vs, 2.0, 0.5)
        v2, _ = g.noise(q, 9.0 * vs, 3.0, 0.6)
    if "color" in res:
        col = res["color"]
    else:
        pal = L["colors"]
        pfac = fac
        if v1 is not None and len(pal) > 1:
            pfac = g.math("MULTIPLY_ADD", g.sub(v1, 0.5), var * 0.8, fac, clamp=True)
        col = g.ramp(pfac, pal)
    if v1 is not None:
        val = g.add(g.madd(g.sub(v1, 0.5), var * 1.2, 1.0), g.mul(g.sub(v2, 0.5), var * 0.8))
        col = g.hsv(col, g.madd(g.sub(v2, 0.5), var * 0.06, 0.5),
                    g.madd(g.sub(v1, 0.5), var * 0.5, 1.0), val)
    r0, r1 = L["roughness"]
    rfac = fac if v2 is None else g.math("MULTIPLY_ADD", g.sub(v2, 0.5), var, fac, clamp=True)
    lrough = g.lerp(r0, r1, rfac) if r0 != r1 else r0
    lmetal = L["metallic"]
    gap = res.get("gap")
    if gap is not None and gap != 0.0:
        col = g.mix(gap, col, tuple(L["gap_color"]))
        lrough = g.lerp(lrough, L["gap_roughness"], gap)
        if lmetal > 0:
            lmetal = g.mul(lmetal, g.sub(1.0, gap))

    # Where this layer shows: its own mask, coverage patches, inside the last layout.
    K = res.get("mask")
    if L["coverage"] < 1.0:
        n, _ = g.noise(q, L["coverage_scale"], 3.0, 0.55)
        t = 0.5 + (0.5 - L["coverage"]) * 0.3
        s = 0.1 * L["coverage_sharpness"]
        cov = g.smooth(t - s, t + s, n)
        K = cov if K is None else g.mul(K, cov)
    if L["inside_only"] and ctx["inside"] is not None:
        K = ctx["inside"] if K is None else g.mul(K, ctx["inside"])

    if L.get("opacity", 1.0) < 1.0:
        K = L["opacity"] if K is None else g.mul(K, L["opacity"])

    h = res.get("height")
    if h is not None:
        h = g.mul(h, L["height"]) if L["height"] != 1.0 else h
        hk = h if K is None else g.mul(h, K)
        if height is None:
            height = hk
        elif L["height_mode"] == "add":
            height = g.add(height, hk)
        else:
            height = g.lerp(height, h, K if K is not None else 1.0)

    if K is None:
        color, rough, metal = col, lrough, lmetal
    else:
        color = g.mix(K, color, col)
        rough = g.lerp(rough, lrough, K)
        metal = g.lerp(metal, lmetal, K)

    if "cell" in res:
        ctx["cell"] = res["cell"]
        ctx["inside"] = res.get("inside")
    return color, rough, metal, height


def _tint(g, color, tint, inst_color, vals):
    if inst_color is None or tint == "none":
        return color
    if tint == "replace":
        return tuple(float(x) for x in inst_color)  # never a template (shared_key)

    def scaled(i):
        c = tuple(float(x) for x in i["color"])
        m = max(max(c), 1e-6)
        return tuple(x / m for x in c) + (1.0,)

    out = g.mix(1.0, color, (1.0, 1.0, 1.0), blend="MULTIPLY")
    vals.put(out.node.inputs["Color2"], scaled)
    return out


# --- user node groups --------------------------------------------------------------------
#
# The ClevrTex convention as the public generator (karazijal/clevrtex-generation,
# `blender_utils.load_material` / `add_material`) uses it: one `.blend` per material holding a
# node group named after the file; its image textures are referenced relative to the `.blend`
# (`//textures/...`). The group's inputs `Color`, `Random`, `Scale` and `Displacement` (also
# spelt `Displacement Strength`) are driven by the instance, any other input keeps the
# `.blend`'s default, as there; the `Shader` (or `BSDF`, `Surface`) output feeds the surface
# and the `Displacement` output the material's displacement (true displacement only where the
# scene displaces, otherwise bump). The Rust side first inspects every user group
# (`inspect_blend`) and checks every texture it reads before any image is rendered; the recipe
# then names the group and maps each texture to the run-private copy of the checked file
# (`images`); the `.blend` itself is such a copy.

_GROUPS = {}
# Inputs the convention drives; every other input keeps the `.blend`'s default.
DRIVEN_INPUTS = ("Color", "Random", "Scale", "Displacement", "Displacement Strength")
# Names of the surface output, in the order tried (the public generator's order).
SURFACE_OUTPUTS = ("Shader", "BSDF", "Surface")
# The output added to a group without a base-colour output, for the albedo pass.
BASE_OUTPUT = "Base Color"


def _stem(path):
    import os

    return os.path.splitext(os.path.basename(path))[0]


def _load_group(path, group, images=None):
    """The node group of the `.blend` at `path` (`group`, its name in the file, else the one
    named after the file, else the first with a surface output) and that name. Loaded once
    per worker and held by reference: another file's group of the same name, loaded too, is
    renamed `.001` by Blender and never confused with it."""
    key = (path, group)
    if key in _GROUPS:
        try:
            ng, name = _GROUPS[key]
            if ng.name in bpy.data.node_groups:
                return ng, name
        except ReferenceError:
            pass  # removed, e.g. by the factory reset of a `material` request: load again
    with bpy.data.libraries.load(path, link=False) as (src, dst):
        names = list(src.node_groups)
        # The group named after the file, as the public generator appends it; else all
        # (the first with a surface output is used).
        want = group if group is not None else (_stem(path) if _stem(path) in names else None)
        requested = [want] if want in names else names
        dst.node_groups = list(requested)
    # The loaded groups beside their names in the file (the loaded ones may be renamed).
    candidates = [(ng, n) for ng, n in zip(dst.node_groups, requested) if ng is not None]
    chosen = None
    for ng, n in candidates:
        outs = {s.name for s in _group_outputs(ng)}
        if want is not None and n != want:
            continue
        if outs & set(SURFACE_OUTPUTS):
            chosen = (ng, n)
            break
    if chosen is None:
        raise ValueError(
            "no node group%s with a `Shader`, `BSDF` or `Surface` output in `%s`"
            % ("" if want is None else " named `%s`" % want, path))
    for ng, _ in candidates:
        ng.use_fake_user = True
    if images is not None:
        _pin_images(chosen[0], images, path)
    _GROUPS[key] = chosen
    return chosen


def _group_outputs(ng):
    if hasattr(ng, "outputs"):
        return list(ng.outputs)
    return [s for s in ng.interface.items_tree if getattr(s, "in_out", "") == "OUTPUT"]


def _group_inputs(ng):
    if hasattr(ng, "inputs"):
        return list(ng.inputs)
    return [s for s in ng.interface.items_tree if getattr(s, "in_out", "") == "INPUT"]


def _socket_type(s):
    return getattr(s, "type", None) or getattr(s, "socket_type", "")


def _images(ng, seen=None):
    """Every image an image-texture node of `ng` (or of a group inside it) reads."""
    seen = set() if seen is None else seen
    out = []
    if ng.name in seen:
        return out
    seen.add(ng.name)
    for node in ng.nodes:
        img = getattr(node, "image", None)
        if img is not None and img not in out:
            out.append(img)
        sub = getattr(node, "node_tree", None)
        if node.type == "GROUP" and sub is not None:
            out.extend(i for i in _images(sub, seen) if i not in out)
    return out


def _image_path(img):
    return bpy.path.abspath(img.filepath, library=img.library)


def _packed_key(i):
    """The key of the `i`-th image of a group (`_images` order) when it is packed."""
    return "packed:%d" % i


def _pin_images(ng, images, path):
    """Point every texture of `ng` at the copy of the file the Rust side checked (`images`:
    path as Blender resolves it, or `packed:<n>` for a packed image -> the checked copy); a
    texture it did not check is an error. A packed image is unpacked (its data dropped, no
    file written) and read from the checked copy of its bytes instead."""
    for i, img in enumerate(_images(ng)):
        if img.source in ("GENERATED", "VIEWER"):
            continue
        if img.packed_file is not None:
            key = _packed_key(i)
            if key not in images:
                raise ValueError("packed image `%s` of `%s` was not checked before the run"
                                 % (img.name, path))
            img.unpack(method="REMOVE")
            img.source = "FILE"
            img.filepath = images[key]
            continue
        p = _image_path(img)
        if p not in images:
            raise ValueError("texture `%s` of `%s` was not checked before the run" % (p, path))
        img.filepath = images[p]


def inspect_blend(path, group=None, packed_dir=None):
    """What the Rust side checks before a run: the group used (by its name in the file), its
    inputs and outputs, and every image it reads (nothing is loaded but the data blocks: no
    pixels). The bytes of each packed image are written into `packed_dir` for the Rust side
    to check, as they are (no pixels decoded here); a generated image reports its size."""
    ng, name = _load_group(path, group)
    images = []
    for i, img in enumerate(_images(ng)):
        entry = {
            "name": img.name,
            "path": _image_path(img),
            "source": img.source,
            "packed": img.packed_file is not None,
        }
        if img.source == "GENERATED":
            entry["width"] = int(img.generated_width)
            entry["height"] = int(img.generated_height)
        if img.packed_file is not None and packed_dir is not None:
            f = os.path.join(packed_dir, str(i))
            # The run's private folder: a file left by a worker that died mid-request is
            # replaced; nothing at the name is followed (exclusive, no-follow create).
            try:
                os.unlink(f)
            except FileNotFoundError:
                pass
            fd = os.open(f, os.O_WRONLY | os.O_CREAT | os.O_EXCL | os.O_NOFOLLOW, 0o600)
            with os.fdopen(fd, "wb") as out:
                out.write(img.packed_file.data)
            entry["file"] = f
            entry["key"] = _packed_key(i)
        images.append(entry)
    return {
        "group": name,
        "inputs": [{"name": s.name, "type": _socket_type(s)} for s in _group_inputs(ng)],
        "outputs": [{"name": s.name, "type": _socket_type(s)} for s in _group_outputs(ng)],
        "images": images,
    }


def _surface_bsdf(ng, socket):
    """The Principled BSDF feeding `socket` (a group output input), through mix and add
    shaders and reroutes; None if there is none."""
    todo = [socket]
    while todo:
        s = todo.pop(0)
        for link in s.links:
            n = link.from_node
            if n.type == "BSDF_PRINCIPLED":
                return n
            todo.extend(i for i in n.inputs if i.is_linked)
    return None


def _add_base_output(ng):
    """Give a group without a base-colour output one (the albedo pass): the base colour of
    the Principled BSDF behind its surface output. Added once per loaded group."""
    if BASE_OUTPUT in {s.name for s in _group_outputs(ng)} or "Color" in {
            s.name for s in _group_outputs(ng)}:
        return
    gout = next((n for n in ng.nodes if n.type == "GROUP_OUTPUT" and n.is_active_output),
                None) or next((n for n in ng.nodes if n.type == "GROUP_OUTPUT"), None)
    if gout is None:
        return
    surface = next((gout.inputs[n] for n in SURFACE_OUTPUTS if n in gout.inputs), None)
    bsdf = _surface_bsdf(ng, surface) if surface is not None else None
    if bsdf is None:
        return
    base = compat.principled_input(bsdf, "Base Color")
    compat.add_group_output(ng, BASE_OUTPUT, "NodeSocketColor")
    target = gout.inputs[BASE_OUTPUT]
    if base.is_linked:
        ng.links.new(base.links[0].from_socket, target)
    else:
        rgb = ng.nodes.new("ShaderNodeRGB")
        rgb.outputs[0].default_value = tuple(base.default_value)
        ng.links.new(rgb.outputs[0], target)


def _socket_value(kind, v):
    """A driven input's value for a socket of type `kind` (RGBA without its alpha 1.0)."""
    if kind == "RGBA":
        return v[:3] if isinstance(v, tuple) else (v, v, v)
    if kind == "VECTOR":
        return (v, v, v) if not isinstance(v, tuple) else v[:3]
    return v if not isinstance(v, tuple) else v[0]


def _driven(instance, displace):
    """The group inputs the convention drives, name -> value, for `instance`."""
    values = {"Random": float(instance.get("random") or 0.0)}
    if instance.get("color") is not None:
        values["Color"] = tuple(float(x) for x in instance["color"])
    if instance.get("scale") is not None:
        values["Scale"] = float(instance["scale"])
    if displace:
        d = float(instance.get("displacement") or 0.0)
        values["Displacement"] = d
        values["Displacement Strength"] = d
    return values


def _build_blend(nt, out, recipe, instance, displace, albedo, vals):
    ng, _ = _load_group(recipe["path"], recipe.get("group"), recipe.get("images"))
    if albedo:
        _add_base_output(ng)
    node = nt.nodes.new("ShaderNodeGroup")
    node.node_tree = ng
    for i, sock in enumerate(node.inputs):
        if sock.name not in _driven(instance, displace):
            continue
        kind = sock.type

        def fn(inst, name=sock.name, kind=kind):
            return _socket_value(kind, _driven(inst, displace)[name])

        vals.put(sock, (lambda inst, fn=fn: fn(inst) + (1.0,)) if kind == "RGBA" else fn)
    shader = next((node.outputs[n] for n in SURFACE_OUTPUTS if n in node.outputs), None)
    nt.links.new(shader, out.inputs["Surface"])
    # The base colour: the group's `Color` or `Base Color` output (added above when it had
    # none, from the Principled BSDF behind its surface).
    base = node.outputs.get("Color") or node.outputs.get(BASE_OUTPUT)
    if albedo and base is not None:
        aov = nt.nodes.new("ShaderNodeOutputAOV")
        compat.set_aov_name(aov, ALBEDO_AOV)
        nt.links.new(base, aov.inputs["Color"])
    # Linked always, as the public generator does: true displacement where the scene
    # displaces (method BOTH), bump from the same output otherwise (method BUMP), so the
    # geometry, and with it mask and depth, depends only on the scene.
    disp = node.outputs.get("Displacement")
    if disp is not None:
        nt.links.new(disp, out.inputs["Displacement"])


# --- PBR texture folders -----------------------------------------------------------------

# Colour maps are sRGB (JPEG, 8- and 16-bit PNG) or linear (OpenEXR); every other map is
# data.
NON_COLOR = "Non-Color"


def _pbr_image(name, path, data):
    """A map of a PBR folder, loaded once per worker (kept across scenes by a fake user)."""
    if not os.path.isfile(path):
        raise ValueError("material `%s`: texture `%s` does not exist" % (name, path))
    img = bpy.data.images.load(path, check_existing=True)
    # An image Blender cannot decode has no pixels and would render pink: refuse it.
    if img.size[0] == 0 or img.size[1] == 0:
        raise ValueError("material `%s`: Blender cannot read texture `%s`" % (name, path))
    if data:
        if img.colorspace_settings.name != NON_COLOR:
            img.colorspace_settings.name = NON_COLOR
    elif img.file_format != "OPEN_EXR" and img.colorspace_settings.name != "sRGB":
        img.colorspace_settings.name = "sRGB"
    img.use_fake_user = True
    return img


def _triplanar(g, p, normal, tile):
    """The three axis projections of `p` (one repeat per `tile`) and their weights
    (|normal|^4, normalised): u, v along (y, z) for x, (x, z) for y, (x, y) for z."""
    x, y, z = g.sep(g.vscale(p, 1.0 / tile))
    uvs = (g.comb(y, z, 0.0), g.comb(x, z, 0.0), g.comb(x, y, 0.0))
    a = g.vmath("ABSOLUTE", normal)
    a2 = g.vmath("MULTIPLY", a, a)
    a4 = g.vmath("MULTIPLY", a2, a2)
    total = g.vmath("DOT_PRODUCT", a4, (1.0, 1.0, 1.0))
    w = g.sep(g.vmath("SCALE", a4, scale=g.div(1.0, total)))
    return uvs, w


def _samples(g, img, uvs):
    out = []
    for uv in uvs:
        n = g.node("ShaderNodeTexImage", interpolation="Linear", extension="REPEAT")
        n.image = img
        g.set(n.inputs["Vector"], uv)
        out.append(n.outputs["Color"])
    return out


def _blend3(g, vs, w):
    acc = g.vmath("SCALE", vs[0], scale=w[0])
    for v, wi in zip(vs[1:], w[1:]):
        acc = g.vmath("ADD", acc, g.vmath("SCALE", v, scale=wi))
    return acc


def _pbr_normal(g, samples, w, normal, dx):
    """Tangent-space normal map samples to a world-space shading normal: per projection
    t = 2c - 1 (DirectX: green flipped), added along that projection's u and v axes to the
    object normal (whiteout-style blend), normalised, to world space."""
    gy = -2.0 if dx else 2.0
    ds = []
    for axis, c in enumerate(samples):
        t = g.vmath("MULTIPLY_ADD", c, (2.0, gy, 2.0))
        t.node.inputs[2].default_value = (-1.0, -gy / 2.0, -1.0)
        tx, ty, _ = g.sep(t)
        ds.append((g.comb(0.0, tx, ty), g.comb(tx, 0.0, ty), g.comb(tx, ty, 0.0))[axis])
    n = g.vmath("NORMALIZE", g.vmath("ADD", normal, _blend3(g, ds, w)))
    vt = g.node("ShaderNodeVectorTransform", vector_type="NORMAL",
                convert_from="OBJECT", convert_to="WORLD")
    g.set(vt.inputs["Vector"], n)
    return g.vmath("NORMALIZE", vt.outputs["Vector"])


def _build_pbr(nt, out, name, recipe, instance, displace, albedo, vals):
    g = Graph(nt)
    p, normal = _coords(g, recipe, vals)
    uvs, w = _triplanar(g, p, normal, float(recipe.get("tile") or 1.0))
    maps = recipe.get("maps") or {}

    def channels(key, data):
        if not maps.get(key):
            return None
        img = _pbr_image(name, maps[key], data)
        return g.sep(_blend3(g, _samples(g, img, uvs), w))

    color_img = _pbr_image(name, maps["color"], False)
    color = _blend3(g, _samples(g, color_img, uvs), w)
    color = _tint(g, color, recipe.get("tint", "multiply"), instance.get("color"), vals)
    arm = channels("arm", True)
    rough = channels("roughness", True)
    metal = channels("metallic", True)
    rough = rough[0] if rough else (arm[1] if arm else 0.5)
    metal = metal[0] if metal else (arm[2] if arm else 0.0)

    bsdf = _principled(g, color, rough, metal, 0.5, albedo)
    if maps.get("normal"):
        img = _pbr_image(name, maps["normal"], True)
        dx = recipe.get("normal_convention") == "dx"
        _set_bsdf(g, bsdf, "Normal", _pbr_normal(g, _samples(g, img, uvs), w, normal, dx))
    nt.links.new(compat.principled_output(nt, bsdf, color), out.inputs["Surface"])
    relief = float(recipe.get("relief") or 0.0)
    if displace and relief > 0 and maps.get("displacement"):
        height = channels("displacement", True)[0]
        _displace(g, nt, out, vals, height, relief)
        return True
    return False
