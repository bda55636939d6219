"""Why a displaced surface renders darker on one Blender than another (issue 50; dev only).

    blender -b --factory-startup --python-exit-code 1 \
        --python blender_scripts/dev/displace_parity_probe.py -- \
        --materials materials.json --scene SCENE.json --material NAME [--as backdrop|object] \
        [--displacement 0.35] [--size 96x72] [--samples 16] [--threads 1] [--no-objects] \
        [--set KEY=VALUE ...] [--out DIR]
    .venv-bpy/bin/python blender_scripts/dev/displace_parity_probe.py --materials ... (the same)

(any Python with bpy, 5.0 too: its multi-part EXR is written again interleaved to be read)

`materials.json` is `clevrtex materials json`, SCENE.json a scene file of `clevrtex sample`
(one with a displaced backdrop: variant `full`). The scene is built as the bridge builds it
(builder.build, shading.assign_materials, materials.build_material with compat's switches),
with material NAME on the backdrop (`--as backdrop`, displacement `--displacement`; 0: no
true displacement) or on every object (`--as object`, the backdrop keeps the scene's own);
`--no-objects` leaves the objects out. Rendered once at `--samples` (Cycles seed 0, CPU) with
the combined, depth and object-index passes, read back without numpy (exr_dump), and printed
as one line:

    PROBE <blender> <material> <as> <sets> lum_bd=.. lum_obj=.. lum_all=.. depth_bd=.. \
        depth_sd_bd=.. n_bd=..

lum_*: mean linear luminance (Rec. 709 weights) of the backdrop pixels (object index 0), the
object pixels and all pixels; depth_bd / depth_sd_bd: mean and standard deviation of the
backdrop pixels' camera depth (the relief: a surface displaced differently sits at another
depth); n_bd: backdrop pixels.

`--set KEY=VALUE` (repeatable; applied after the build, to split a difference by setting):
  method=BUMP|DISPLACEMENT|BOTH  every material's displacement method
  bump=0                         unlink every Bump node's output (no bump on the shading
                                 normal; the displacement is kept)
  bump_width_facing=A,B          every Bump node's Filter Width (4.4+) fed A + B x Facing
                                 (Layer Weight, blend 0.5: 0 face-on, 1 at grazing)
  bump_correction=0|1            every material's Bump Map Correction (4.0+; 3.x always
                                 keeps a bumped reflection above the surface)
  bump_distance=F                multiply every Bump node's Distance
  bump_width=F                   every Bump node's Filter Width (4.4+)
  derived_bump_undisplaced=F     (4.x, with method=DISPLACEMENT, set before the build) 3.4's
                                 bump derived from the displacement, rebuilt as a Bump node of
                                 filter width F whose height is the material's height
                                 evaluated where the surface was before its displacement
                                 (the texture coordinate moved back along the normal by the
                                 displacement at the shading point), in front of the recipe's
                                 Bump node
  derived_base_up=1              (set before the build, with derived_bump_undisplaced) that
                                 Bump node's base normal +z (the undisplaced floor's)
  derived_base_attr=1            (with derived_bump_undisplaced) its base normal the
                                 undisplaced backdrop's: the base mesh's vertex normals as a
                                 point attribute, interpolated (3.x's BOTH keeps the vertex
                                 normals undisplaced and bumps them by the full gradient)
  dicing_rate=F                  Cycles' render dicing rate (pixels)
  offscreen_dicing_scale=F       Cycles' offscreen dicing scale
  max_subdivisions=N             Cycles' max subdivisions
  adaptive=0|1                   adaptive subdivision on every object that has it
  feature_set=SUPPORTED|EXPERIMENTAL
  midlevel=F, disp_scale=F       every Displacement node's Midlevel / Scale multiplied
  space=OBJECT|WORLD             every Displacement node's space
  parity_off=KEY[+KEY..]|all     compat.PARITY switches off before the materials are built
  coat_light_pdf=T               compat's COAT_LIGHT_PDF (4.x; before the materials are
                                 built)
  disney=D,X                     compat's Disney diffuse constants cos^2 theta_d = D and
                                 F_L = X (4.x; before the materials are built)
  normal=geometry                every Principled BSDF's Normal input unlinked
  glossy=0                       every Principled BSDF's specular level 0 and the added
                                 specular and coat lobes' weight 0 (diffuse only; 4.x's
                                 metal lobe kept, as 3.x keeps its metal)
  coat=F                         every clearcoat multiplied by F (3.x: the Clearcoat input;
                                 4.x: the weight of the coat lobes of compat's `layers`)
  metallic=0                     every Principled BSDF's Metallic 0 (unlinked; on 4.x
                                 also the added metal lobe's weight)
  roughness=F                    every Principled BSDF's Roughness F (unlinked; 4.x's
                                 Disney diffuse factor keeps the built roughness: add
                                 parity_off=disney_diffuse to compare the bare BSDFs)
  sheen=F                        every Principled BSDF's Sheen Weight (4.x) multiplied by F
  diffuse_roughness=F            every Principled BSDF's Diffuse Roughness (4.3+) fed F times
                                 (what feeds its Roughness - R0), clamped to 0..1
  diffuse_roughness_from=R0      R0 of `diffuse_roughness` (default 0; give it first)
  derived_bump_glossy=F          the same on the added specular, metal and coat lobes only
                                 (4.x; the diffuse's node keeps its normal)
  derived_bump=F                 Cycles' bump derived from the displacement built as a Bump
                                 node of filter width F (use with method=DISPLACEMENT)
  lights=NAME                    only light NAME (`sun`, an area light's name)
  diffuse_only=1                 every material's surface a white diffuse BSDF (geometry
                                 and displacement kept)
"""

import argparse
import json
import math
import os
import sys
import tempfile
import time

import bpy

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, os.path.dirname(HERE))
sys.path.insert(0, HERE)

import builder  # noqa: E402
import compat  # noqa: E402
import exr_dump  # noqa: E402
import materials  # noqa: E402
import passes  # noqa: E402


def parse_args():
    argv = sys.argv[sys.argv.index("--") + 1:] if "--" in sys.argv else sys.argv[1:]
    p = argparse.ArgumentParser(prog="displace_parity_probe.py")
    p.add_argument("--materials", required=True)
    p.add_argument("--scene", required=True)
    p.add_argument("--material", required=True, action="append",
                   help="repeatable: each material rendered in turn")
    p.add_argument("--as", dest="role", default="backdrop", choices=["backdrop", "object"])
    p.add_argument("--displacement", type=float, default=0.35)
    p.add_argument("--size", default="96x72")
    p.add_argument("--samples", type=int, default=16)
    p.add_argument("--threads", type=int, default=1)
    p.add_argument("--no-objects", action="store_true")
    p.add_argument("--set", action="append", default=[], dest="sets")
    p.add_argument("--out", default=None, help="keep the EXRs here (default: a temp dir)")
    p.add_argument("--factory-startup", action="store_true",
                   help="(what clevrtex passes a bpy module; factory settings are used anyway)")
    return p.parse_args(argv)


def trees():
    out = [m.node_tree for m in bpy.data.materials if m.node_tree is not None]
    return out + list(bpy.data.node_groups)


def nodes_of(kind):
    for t in trees():
        for n in t.nodes:
            if n.type == kind:
                yield t, n


def unlink(tree, socket):
    for link in list(socket.links):
        tree.links.remove(link)


DR_FROM = [0.0]
DERIVED_BASE_UP = [False]


def derived_bumps(width):
    """[(tree, Bump node)]: in every material that displaces, a new Bump node of the
    Displacement node's height and scale and filter width `width` (3.4's bump derived from the
    displacement, rebuilt; its output left unlinked)."""
    out = []
    for m in bpy.data.materials:
        t = m.node_tree
        if t is None:
            continue
        disp = next((n for n in t.nodes if n.type == "DISPLACEMENT"), None)
        if disp is None or not disp.inputs["Height"].is_linked:
            continue
        b = t.nodes.new("ShaderNodeBump")
        if "Filter Width" in b.inputs:
            b.inputs["Filter Width"].default_value = width
        t.links.new(disp.inputs["Height"].links[0].from_socket, b.inputs["Height"])
        b.inputs["Distance"].default_value = disp.inputs["Scale"].default_value
        out.append((t, b))
    return out


def patch_undisplaced_bump(width):
    """Wrap materials._layer so that, for a material that displaces, the layers are built a
    second time on the texture coordinate moved back by the displacement (p - (h(p) - 0.5) x
    scale x normal, one fixed-point step), and that second height feeds a Bump node of the
    displacement's distance and filter width `width`, linked in front of the recipe's own
    Bump node (else of the Principled BSDF's normal) when the material output gets its
    Displacement (materials._displace)."""
    state = {}
    orig_layer, orig_displace = materials._layer, materials._displace

    def layer(g, p, L, ctx, color, rough, metal, height):
        st = state.setdefault(id(g.nt), {"layers": [], "p": p, "ctx": ctx})
        st["layers"].append(L)
        return orig_layer(g, p, L, ctx, color, rough, metal, height)

    def displace(g, nt, out, vals, height, relief):
        orig_displace(g, nt, out, vals, height, relief)
        st = state.pop(id(g.nt), None)
        if st is None:
            return
        # Back along the object-space normal by the displacement, in texture units: the
        # coordinate is object position x object scale x k + offset; k per layer is folded
        # into p by _coords (its MULTIPLY_ADD node's input 1).
        tc = next(n for n in nt.nodes if n.type == "TEX_COORD")
        shift = g.math("MULTIPLY", g.sub(height, 0.5), 1.0)
        shift.node.label = "du_scale"  # x the displacement's scale, set after the build
        back = g.vscale(tc.outputs["Normal"], shift)
        back = g.vmath("MULTIPLY", back, (1.0, 1.0, 1.0))
        back.node.label = "du_k"  # x the coordinate's scale k, set after the build
        pu = g.vmath("SUBTRACT", st["p"], back)
        ctx = dict(st["ctx"])
        ctx.update({"cell": None, "inside": None, "_normal_xyz": None})
        hu = None
        c, r, m = (0.5, 0.5, 0.5), 0.5, 0.0
        for L in st["layers"]:
            c, r, m, hu = orig_layer(g, pu, L, ctx, c, r, m, hu)
        b = nt.nodes.new("ShaderNodeBump")
        if "Filter Width" in b.inputs:
            b.inputs["Filter Width"].default_value = width
        nt.links.new(hu, b.inputs["Height"])
        b.label = "derived"  # Distance: the displacement's scale, set after the build
        if DERIVED_BASE_UP[0]:
            up = nt.nodes.new("ShaderNodeCombineXYZ")
            up.inputs[2].default_value = 1.0
            nt.links.new(up.outputs[0], b.inputs["Normal"])
        recipe = [n for n in nt.nodes if n.type == "BUMP" and n != b]
        if recipe:
            for n in recipe:
                nt.links.new(b.outputs["Normal"], n.inputs["Normal"])
        else:
            for n in nt.nodes:
                if n.type == "BSDF_PRINCIPLED" and not n.inputs["Normal"].is_linked:
                    nt.links.new(b.outputs["Normal"], n.inputs["Normal"])

    materials._layer, materials._displace = layer, displace


def apply_set(key, value, scene):
    c = scene.cycles
    f = None
    try:
        f = float(value)
    except ValueError:
        pass
    if key == "method":
        for m in bpy.data.materials:
            if m.node_tree is not None:
                compat.set_displacement_method(m, value)
    elif key == "bump":
        for t, n in list(nodes_of("BUMP")):
            unlink(t, n.outputs["Normal"])
    elif key == "bump_width_facing":
        a, b = (float(t) for t in value.split(","))
        for t, n in list(nodes_of("BUMP")):
            if "Filter Width" not in n.inputs:
                continue
            lw = t.nodes.new("ShaderNodeLayerWeight")
            lw.inputs["Blend"].default_value = 0.5
            m = t.nodes.new("ShaderNodeMath")
            m.operation = "MULTIPLY_ADD"
            t.links.new(lw.outputs["Facing"], m.inputs[0])
            m.inputs[1].default_value = b
            m.inputs[2].default_value = a
            t.links.new(m.outputs["Value"], n.inputs["Filter Width"])
    elif key == "bump_correction":
        for m in bpy.data.materials:
            if hasattr(m.cycles, "use_bump_map_correction"):
                m.cycles.use_bump_map_correction = bool(f)
    elif key == "bump_distance":
        for _t, n in nodes_of("BUMP"):
            n.inputs["Distance"].default_value *= f
    elif key == "bump_width":
        for _t, n in nodes_of("BUMP"):
            if "Filter Width" not in n.inputs:
                return "absent"
            n.inputs["Filter Width"].default_value = f
    elif key in ("dicing_rate", "offscreen_dicing_scale"):
        setattr(c, key, f)
    elif key == "max_subdivisions":
        c.max_subdivisions = int(value)
    elif key == "adaptive":
        for o in scene.objects:
            mod = o.modifiers.get("subdivision")
            if mod is not None:
                compat.set_adaptive_subdivision(o, mod, bool(int(value)))
    elif key == "feature_set":
        c.feature_set = value
    elif key in ("midlevel", "disp_scale"):
        name = "Midlevel" if key == "midlevel" else "Scale"
        for _t, n in nodes_of("DISPLACEMENT"):
            n.inputs[name].default_value *= f
    elif key == "space":
        for _t, n in nodes_of("DISPLACEMENT"):
            n.space = value
    elif key == "normal":
        for t, n in list(nodes_of("BSDF_PRINCIPLED")):
            unlink(t, n.inputs["Normal"])
    elif key == "glossy":
        for t, n in list(nodes_of("BSDF_PRINCIPLED")):
            s = compat.principled_input(n, "Specular")
            unlink(t, s)
            s.default_value = 0.0
        for t, n in list(nodes_of("MIX_SHADER")):
            if n.label in ("specular", "coat"):  # the metal's are kept, as on 3.x
                unlink(t, n.inputs["Fac"])
                n.inputs["Fac"].default_value = 0.0 if not n.inputs[1].is_linked else 1.0
    elif key == "coat":
        # 3.x: the Clearcoat input; 4.x: the weight of the coat lobes principled_output adds
        # (the Mix Shaders it labels "coat").
        for t, n in list(nodes_of("BSDF_PRINCIPLED")):
            if "Clearcoat" in n.inputs:
                n.inputs["Clearcoat"].default_value *= f
        for t, n in list(nodes_of("MIX_SHADER")):
            if n.label == "coat":
                n.inputs["Fac"].default_value *= f
    elif key == "metallic":
        # 4.x: also the weights principled_output gives its metal lobe and the principled node
        # beside it, and its specular lobe's 1 - Metallic (Mix Shaders labelled so).
        for t, n in list(nodes_of("BSDF_PRINCIPLED")):
            s = n.inputs["Metallic"]
            unlink(t, s)
            s.default_value = 0.0
        for t, n in list(nodes_of("MIX_SHADER")):
            if n.label in ("metal", "specular"):
                unlink(t, n.inputs["Fac"])
                n.inputs["Fac"].default_value = 0.0
    elif key == "roughness":
        for t, n in list(nodes_of("BSDF_PRINCIPLED")):
            s = n.inputs["Roughness"]
            unlink(t, s)
            s.default_value = f
    elif key == "sheen":
        for _t, n in nodes_of("BSDF_PRINCIPLED"):
            if "Sheen Weight" not in n.inputs:
                return "absent"
            n.inputs["Sheen Weight"].default_value *= f
    elif key == "diffuse_roughness_from":
        DR_FROM[0] = f
    elif key == "diffuse_roughness":
        r0 = DR_FROM[0]
        for t, n in list(nodes_of("BSDF_PRINCIPLED")):
            if "Diffuse Roughness" not in n.inputs:
                return "absent"
            src, dst = n.inputs["Roughness"], n.inputs["Diffuse Roughness"]
            if src.is_linked:
                m = t.nodes.new("ShaderNodeMath")
                m.operation = "MULTIPLY_ADD"
                m.use_clamp = True
                t.links.new(src.links[0].from_socket, m.inputs[0])
                m.inputs[1].default_value = f
                m.inputs[2].default_value = -f * r0
                t.links.new(m.outputs[0], dst)
            else:
                dst.default_value = min(1.0, max(0.0, (src.default_value - r0) * f))
    elif key == "derived_bump":
        # 3.4's bump derived from the displacement, built as a Bump node: the Displacement
        # node's height and scale, filter width F, in front of the recipe's Bump node (else
        # of every Principled BSDF's normal).
        for t, b in derived_bumps(f):
            bumps = [n for n in t.nodes if n.type == "BUMP" and n != b]
            targets = [n.inputs["Normal"] for n in bumps]
            if not targets:
                targets = [n.inputs["Normal"] for n in t.nodes
                           if n.type == "BSDF_PRINCIPLED" and not n.inputs["Normal"].is_linked]
            for sock in targets:
                t.links.new(b.outputs["Normal"], sock)
    elif key == "derived_bump_glossy":
        # The same rebuilt bump, on the normals of the lobes compat's `layers` adds (principled
        # nodes of black base: specular, metal, coat) only, after the recipe's own bump; the
        # principled node that holds the diffuse keeps its normal.
        for t, b in derived_bumps(f):
            recipe = next((n for n in t.nodes if n.type == "BUMP" and n != b), None)
            if recipe is not None:
                t.links.new(recipe.outputs["Normal"], b.inputs["Normal"])
            for n in list(t.nodes):
                base = n.inputs.get("Base Color") if n.type == "BSDF_PRINCIPLED" else None
                if base is not None and not base.is_linked and max(base.default_value[:3]) == 0:
                    t.links.new(b.outputs["Normal"], n.inputs["Normal"])
    elif key == "lights":
        for o in scene.objects:
            if o.type == "LIGHT":
                o.hide_render = o.name != value
    elif key == "diffuse_only":
        for m in bpy.data.materials:
            t = m.node_tree
            if t is None:
                continue
            out = next(n for n in t.nodes if n.type == "OUTPUT_MATERIAL")
            d = t.nodes.new("ShaderNodeBsdfDiffuse")
            d.inputs["Color"].default_value = (0.8, 0.8, 0.8, 1.0)
            t.links.new(d.outputs[0], out.inputs["Surface"])
    elif key == "derived_bump_undisplaced":
        # The values patch_undisplaced_bump's nodes take from the instance (now assigned).
        for m in bpy.data.materials:
            t = m.node_tree
            if t is None:
                continue
            d = next((n for n in t.nodes if n.type == "DISPLACEMENT"), None)
            if d is None:
                continue
            scale = d.inputs["Scale"].default_value
            tc = next(n for n in t.nodes if n.type == "TEX_COORD")
            madd = next(n for n in t.nodes if n.type == "VECT_MATH"
                        and n.operation == "MULTIPLY_ADD" and n.inputs[0].is_linked
                        and n.inputs[0].links[0].from_node.type == "VECT_MATH"
                        and n.inputs[0].links[0].from_node.inputs[0].is_linked
                        and n.inputs[0].links[0].from_node.inputs[0].links[0].from_node == tc)
            for n in t.nodes:
                if n.label == "du_scale":
                    n.inputs[1].default_value = scale
                elif n.label == "du_k":
                    n.inputs[1].default_value = madd.inputs[1].default_value
                elif n.label == "derived":
                    n.inputs["Distance"].default_value = scale
    elif key == "derived_base_attr":
        # The rebuilt derived bump's base normal: the undisplaced surface's, as 3.x's BOTH
        # keeps it (a point attribute of the backdrop's vertex normals, interpolated).
        obj = scene.objects["backdrop"]
        me = obj.data
        a = me.attributes.get("clevrtex_n0") or me.attributes.new(
            "clevrtex_n0", "FLOAT_VECTOR", "POINT")
        for i, v in enumerate(me.vertices):
            a.data[i].vector = v.normal
        for m in bpy.data.materials:
            t = m.node_tree
            if t is None:
                continue
            for b in [n for n in t.nodes if n.type == "BUMP" and n.label == "derived"]:
                at = t.nodes.new("ShaderNodeAttribute")
                at.attribute_name = "clevrtex_n0"
                vt = t.nodes.new("ShaderNodeVectorTransform")
                vt.vector_type = "NORMAL"
                vt.convert_from = "OBJECT"
                vt.convert_to = "WORLD"
                t.links.new(at.outputs["Vector"], vt.inputs[0])
                t.links.new(vt.outputs[0], b.inputs["Normal"])
    elif key in ("parity_off", "disney", "coat_light_pdf", "derived_base_up"):
        pass  # applied before the build
    else:
        raise SystemExit("unknown --set key `%s`" % key)
    return "ok"


def luminance(r, g, b):
    return 0.2126 * r + 0.7152 * g + 0.0722 * b


def measure(path):
    w, h, data = exr_dump.read(path)

    def chan(suffix):
        for k, v in data.items():
            if k.endswith(suffix):
                return v
        raise KeyError(suffix)

    r, g, b = chan("Combined.R"), chan("Combined.G"), chan("Combined.B")
    try:
        idx = chan("IndexOB.X")
    except KeyError:
        idx = chan("Object Index.X")  # 5.0's long pass name
    z = chan("Depth.Z")
    lum = [luminance(r[i], g[i], b[i]) for i in range(w * h)]
    bd = [i for i in range(w * h) if idx[i] == 0.0 and z[i] < 1e9]
    ob = [i for i in range(w * h) if idx[i] > 0.0]

    def mean(xs):
        return sum(xs) / len(xs) if xs else float("nan")

    dz = [z[i] for i in bd]
    mz = mean(dz)
    sd = math.sqrt(mean([(x - mz) ** 2 for x in dz])) if dz else float("nan")
    return {"lum_bd": mean([lum[i] for i in bd]), "lum_obj": mean([lum[i] for i in ob]),
            "lum_all": mean(lum), "depth_bd": mz, "depth_sd_bd": sd, "n_bd": len(bd),
            "n_obj": len(ob)}


def main():
    args = parse_args()
    with open(args.materials, "r", encoding="utf-8") as f:
        catalogue = json.load(f)["materials"]
    w, h = (int(v) for v in args.size.split("x"))
    if compat.is_module():
        compat.factory_startup()
    sets = [s.split("=", 1) for s in args.sets]
    for k, v in sets:
        if k == "parity_off":
            for key in (compat.PARITY if v == "all" else v.split("+")):
                compat.PARITY[key] = False
        elif k == "disney":
            import compat_principled
            d, x = (float(t) for t in v.split(","))
            compat_principled.DISNEY_COS2_D, compat_principled.DISNEY_LIGHT_F = d, x
        elif k == "coat_light_pdf":
            import compat_principled
            compat_principled.COAT_LIGHT_PDF = float(v)
        elif k == "derived_bump_undisplaced":
            patch_undisplaced_bump(float(v))
        elif k == "derived_base_up":
            DERIVED_BASE_UP[0] = bool(int(v))
    out = args.out or tempfile.mkdtemp(prefix="displace_probe_")
    os.makedirs(out, exist_ok=True)
    for name in args.material:
        spec = builder.load_scene_file(args.scene)
        r = spec["render"]
        r["width"], r["height"], r["samples"] = w, h, args.samples
        r["cycles_seed"] = 0
        r.pop("adaptive_threshold", None)
        if args.no_objects:
            spec["objects"] = []
        if args.role == "backdrop":
            bd = spec["backdrop"]["material"]
            bd["name"] = name
            if args.displacement > 0:
                bd["displacement"] = args.displacement
            else:
                bd.pop("displacement", None)
        else:
            for o in spec["objects"]:
                o["material"]["name"] = name
        built = builder.build(spec, (name, time.time()), args.threads)
        builder.assign_materials(built, catalogue, materials.build_material, displacement=True)
        scene = bpy.context.scene
        passes.enable(bpy.context.view_layer, ["rgb", "mask", "depth"])
        done = {}
        for k, v in sets:
            done["%s=%s" % (k, v)] = apply_set(k, v, scene)
        t0 = time.perf_counter()
        bpy.ops.render.render(write_still=False)
        wall = time.perf_counter() - t0
        path = os.path.join(out, "%s_%s.exr" % (name, args.role))
        builder._save(path, "EXR")
        if hasattr(scene.render.image_settings, "use_exr_interleave"):
            # 5.0 writes multi-part EXRs, which exr_dump does not read: again, interleaved.
            scene.render.image_settings.use_exr_interleave = True
            bpy.data.images["Render Result"].save_render(path, scene=scene)
        m = measure(path)
        print("PROBE %s %s %s %s lum_bd=%.5f lum_obj=%.5f lum_all=%.5f depth_bd=%.5f "
              "depth_sd_bd=%.5f n_bd=%d wall=%.1f" % (
                  compat.version_string(), name, args.role,
                  ",".join(k for k, v in done.items() if v == "ok") or "-",
                  m["lum_bd"], m["lum_obj"], m["lum_all"], m["depth_bd"], m["depth_sd_bd"],
                  m["n_bd"], wall), flush=True)


main()
