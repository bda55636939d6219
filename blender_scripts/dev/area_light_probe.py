"""One square area light over a plane, to compare Blender versions' area lights (issue 24; dev).

    blender -b --factory-startup --python-exit-code 1 \
        --python blender_scripts/dev/area_light_probe.py -- CASES.json OUT.jsonl
    .venv-bpy/bin/python blender_scripts/dev/area_light_probe.py CASES.json OUT.jsonl

CASES.json is a list of cases; each is rendered in its own fresh scene and appended to
OUT.jsonl as one JSON line with the case, the Blender version and the mean of every pass
(R, G, B averaged: the light is white). A case (absent keys: the defaults below):

    {"name": "...",
     "material": "diffuse" | "glossy" | "principled",
     "inputs": {"Specular": 0.5, ...},   principled: 3.x input names, set as the bridge sets
                                         them (compat.principled_input/_value/_output)
     "roughness": 0.1,                   glossy: the Glossy BSDF's (GGX)
     "cam_elev": 90,                     degrees above the plane, camera at azimuth 0
     "light_elev": 45,                   degrees above the plane, light at azimuth 180 (the
                                         camera's mirror direction when equal to cam_elev)
     "distance": 5, "size": 0.5, "energy": 100 (3.x watts, through compat.area_light_energy),
     "tilt": 0,                          degrees the light's aim turns away from the origin
                                         (about its horizontal axis: larger emission angle)
     "view": 0.2,                        metres the orthographic camera sees across
     "samples": 256, "seed": 0,
     "parity_off": []}                   compat.PARITY switches off for this case (4.x)

The camera is orthographic, aimed at the origin, 32x32 pixels. At the default `view` every
pixel sees the plane near the origin (and, on a glossy plane seen from the mirror direction,
the middle of the light's reflection: its peak); a wide `view` (e.g. 12) takes in the whole
reflection, whose mean is then its energy. World black, no other light, 1 thread. Compare two versions' OUT.jsonl by case
name (`--compare A.jsonl B.jsonl`, plain python3).
"""

import json
import math
import os
import sys

HERE = os.path.dirname(os.path.abspath(__file__))

DEFAULTS = {"material": "diffuse", "inputs": {}, "roughness": 0.1, "cam_elev": 90.0,
            "light_elev": 45.0, "distance": 5.0, "size": 0.5, "energy": 100.0, "tilt": 0.0,
            "view": 0.2, "samples": 256, "seed": 0, "parity_off": []}
PASSES = ["Combined", "DiffDir", "DiffInd", "DiffCol", "GlossDir", "GlossInd", "GlossCol"]


def compare(a_path, b_path):
    def load(p):
        with open(p) as f:
            return {d["case"]["name"]: d for d in map(json.loads, f)}

    a, b = load(a_path), load(b_path)
    for name, da in a.items():
        db = b.get(name)
        if db is None:
            continue
        ra = da["means"]
        rb = db["means"]
        gl_a = ra["GlossDir"] * ra["GlossCol"] if "GlossCol" in ra else 0.0
        gl_b = rb["GlossDir"] * rb["GlossCol"] if "GlossCol" in rb else 0.0

        def ratio(x, y):
            return x / y if y > 0 else float("nan")

        print("%-28s %s/%s: Combined %.5f / %.5f = %.4f  DiffDir %.4f  GlossDir*Col %.4f" % (
            name, db["blender"], da["blender"], rb["Combined"], ra["Combined"],
            ratio(rb["Combined"], ra["Combined"]), ratio(rb["DiffDir"], ra["DiffDir"]),
            ratio(gl_b, gl_a)))


def look_at(obj, target):
    import mathutils

    d = mathutils.Vector(target) - obj.location
    obj.rotation_euler = d.to_track_quat("-Z", "Y").to_euler()


def direction(elev_deg, azim_deg):
    e, a = math.radians(elev_deg), math.radians(azim_deg)
    return (math.cos(e) * math.cos(a), math.cos(e) * math.sin(a), math.sin(e))


def build_case(case):
    import bpy

    sys.path.insert(0, os.path.dirname(HERE))
    import compat

    bpy.ops.wm.read_factory_settings(use_empty=True)
    scene = bpy.context.scene
    scene.render.engine = "CYCLES"
    c = scene.cycles
    c.device = "CPU"
    c.samples = case["samples"]
    c.seed = case["seed"]
    if hasattr(c, "use_adaptive_sampling"):
        c.use_adaptive_sampling = False
    if hasattr(c, "use_denoising"):
        c.use_denoising = False
    if hasattr(c, "use_light_tree"):
        c.use_light_tree = False
    c.blur_glossy = 0.0
    scene.render.threads_mode = "FIXED"
    scene.render.threads = 1
    scene.render.resolution_x = scene.render.resolution_y = 32
    scene.render.resolution_percentage = 100
    world = bpy.data.worlds.new("black")
    world.use_nodes = True
    world.node_tree.nodes["Background"].inputs["Strength"].default_value = 0.0
    scene.world = world

    bpy.ops.mesh.primitive_plane_add(size=40.0)
    plane = bpy.context.active_object
    mat = bpy.data.materials.new("m")
    mat.use_nodes = True
    nt = mat.node_tree
    for n in list(nt.nodes):
        nt.nodes.remove(n)
    out = nt.nodes.new("ShaderNodeOutputMaterial")
    kind = case["material"]
    if kind == "diffuse":
        n = nt.nodes.new("ShaderNodeBsdfDiffuse")
        n.inputs["Color"].default_value = (0.8, 0.8, 0.8, 1.0)
        shader = n.outputs["BSDF"]
    elif kind == "glossy":
        n = nt.nodes.new("ShaderNodeBsdfGlossy")
        n.distribution = "GGX"
        n.inputs["Color"].default_value = (1.0, 1.0, 1.0, 1.0)
        n.inputs["Roughness"].default_value = case["roughness"]
        shader = n.outputs["BSDF"]
    elif kind == "principled":
        n = nt.nodes.new("ShaderNodeBsdfPrincipled")
        compat.setup_principled(n)
        for name, value in case["inputs"].items():
            sock = compat.principled_input(n, name)
            v = compat.principled_value(name, value)
            if isinstance(v, list):
                v = tuple(v)
            sock.default_value = v
        shader = compat.principled_output(nt, n, tuple(n.inputs["Base Color"].default_value))
    else:
        raise SystemExit("unknown material `%s`" % kind)
    nt.links.new(shader, out.inputs["Surface"])
    plane.data.materials.append(mat)

    cam_data = bpy.data.cameras.new("cam")
    cam_data.type = "ORTHO"
    cam_data.ortho_scale = case["view"]
    cam = bpy.data.objects.new("cam", cam_data)
    scene.collection.objects.link(cam)
    cam.location = tuple(10.0 * v for v in direction(case["cam_elev"], 0.0))
    look_at(cam, (0.0, 0.0, 0.0))
    scene.camera = cam

    light = bpy.data.lights.new("area", "AREA")
    light.shape = "SQUARE"
    light.size = case["size"]
    light.energy = compat.area_light_energy(case["energy"])
    light.color = (1.0, 1.0, 1.0)
    obj = bpy.data.objects.new("area", light)
    scene.collection.objects.link(obj)
    obj.location = tuple(case["distance"] * v for v in direction(case["light_elev"], 180.0))
    look_at(obj, (0.0, 0.0, 0.0))
    # Tilt: turn the light about its own horizontal (local X) axis, away from the origin.
    obj.rotation_mode = "XYZ"
    import mathutils

    m = obj.matrix_world.to_3x3() @ mathutils.Matrix.Rotation(math.radians(case["tilt"]), 3, "X")
    obj.rotation_euler = m.to_euler()
    if hasattr(obj, "visible_camera"):
        obj.visible_camera = False  # seen in reflection only, not in front of the camera

    vl = bpy.context.view_layer
    for flag in ("use_pass_diffuse_direct", "use_pass_diffuse_indirect", "use_pass_diffuse_color",
                 "use_pass_glossy_direct", "use_pass_glossy_indirect", "use_pass_glossy_color"):
        setattr(vl, flag, True)
    return scene


def render_case(case, tmp):
    import bpy

    sys.path.insert(0, os.path.dirname(HERE))
    sys.path.insert(0, HERE)
    import compat
    import exr_dump

    saved = dict(compat.PARITY)
    for key in case["parity_off"]:
        if key in compat.PARITY:
            compat.PARITY[key] = False
    try:
        scene = build_case(case)
    finally:
        compat.PARITY.update(saved)
    bpy.ops.render.render(write_still=False)
    compat.set_exr_multilayer_output(scene.render.image_settings, "RLE")
    bpy.data.images["Render Result"].save_render(tmp, scene=scene)
    w, h, chans = exr_dump.read(tmp)
    means = {}
    for p in PASSES:
        vals = []
        for ch in "RGB":
            key = [k for k in chans if k.split(".")[-2:] == [p, ch]]
            if key:
                v = chans[key[0]]
                vals.append(sum(v) / len(v))
        if vals:
            means[p] = sum(vals) / len(vals)
    return {"blender": compat.version_string(), "case": case, "means": means}


def main():
    argv = sys.argv[sys.argv.index("--") + 1:] if "--" in sys.argv else sys.argv[1:]
    argv = [a for a in argv if a != "--factory-startup"]  # bpy started as the bridge is
    if argv and argv[0] == "--compare":
        compare(argv[1], argv[2])
        return
    cases_path, out_path = argv
    with open(cases_path) as f:
        cases = json.load(f)
    tmp = out_path + ".tmp.exr"
    for raw in cases:
        case = dict(DEFAULTS)
        case.update(raw)
        res = render_case(case, tmp)
        with open(out_path, "a") as f:
            f.write(json.dumps(res) + "\n")
        print("%s %s %s" % (res["blender"], case["name"],
                            " ".join("%s=%.5f" % kv for kv in res["means"].items())), flush=True)
    if os.path.exists(tmp):
        os.remove(tmp)


main()
