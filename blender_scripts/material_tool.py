"""Material scenes of `clevrtex materials sheet|check|stats|cost`: the worker's `material`
request (docs/bridge-protocol.md).

`render(req, threads)` resets Blender to factory settings, builds one small scene around the
material `req["name"]` (recipe `req["recipe"]`), renders it to `<out_dir>/<name>.png` and
returns the reply's fields. Modes:

- sheet: a sphere and a cube of the material on a grey floor, name written underneath;
- tile: the material on a flat square seen straight down, flat-lit (distinctness stats);
- check: like sheet, plus the share of pink (missing-texture) pixels;
- cost: a sphere filling the frame at `samples`, timed (relative cost vs `plain`);
- density: a small and a large cube side by side, orthographic from the front, plus the
  stripe period measured on each.
"""

import os
import time

import bpy

import compat
import materials


class Options:
    """The per-request settings the scene builders read."""

    def __init__(self, req):
        self.displacement = float(req.get("displacement", 0.0))
        self.random = float(req.get("random", 0.37))


def reset_scene():
    bpy.ops.wm.read_factory_settings(use_empty=True)
    scene = bpy.context.scene
    scene.render.engine = "CYCLES"
    scene.cycles.device = "CPU"
    scene.cycles.use_denoising = False
    scene.cycles.use_adaptive_sampling = False
    scene.render.film_transparent = False
    compat.set_view_look(scene.view_settings, "Filmic", "Medium High Contrast")
    compat.set_png_output(scene.render.image_settings)
    world = bpy.data.worlds.new("world")
    world.use_nodes = True
    world.node_tree.nodes["Background"].inputs["Color"].default_value = (0.05, 0.05, 0.05, 1)
    scene.world = world
    return scene


def add_mesh(kind, scale, location, rotation_z=0.0):
    if kind == "sphere":
        bpy.ops.mesh.primitive_uv_sphere_add(segments=48, ring_count=24, radius=1.0)
        bpy.ops.object.shade_smooth()
    elif kind == "cube":
        bpy.ops.mesh.primitive_cube_add(size=2.0)
    else:
        bpy.ops.mesh.primitive_plane_add(size=2.0)
    ob = bpy.context.object
    ob.scale = (scale, scale, scale)
    ob.location = location
    ob.rotation_euler = (0.0, 0.0, rotation_z)
    return ob


def add_camera(location, look_at, lens=50.0, ortho=None):
    cam = bpy.data.cameras.new("cam")
    if ortho is not None:
        cam.type = "ORTHO"
        cam.ortho_scale = ortho
    cam.lens = lens
    ob = bpy.data.objects.new("cam", cam)
    bpy.context.scene.collection.objects.link(ob)
    ob.location = location
    d = [look_at[i] - location[i] for i in range(3)]
    from mathutils import Vector

    ob.rotation_euler = Vector(d).to_track_quat("-Z", "Y").to_euler()
    bpy.context.scene.camera = ob
    return ob


def add_light(kind, location, energy, size=2.0, rotation=(0.0, 0.0, 0.0)):
    light = bpy.data.lights.new(kind, kind)
    if kind == "SUN":
        light.energy = compat.sun_strength(energy)
    else:
        light.energy = compat.area_light_energy(energy)
    if kind == "AREA":
        light.size = size
    ob = bpy.data.objects.new(kind, light)
    bpy.context.scene.collection.objects.link(ob)
    ob.location = location
    ob.rotation_euler = rotation
    return ob


def aim(ob, target):
    from mathutils import Vector

    d = Vector(target) - ob.location
    ob.rotation_euler = d.to_track_quat("-Z", "Y").to_euler()


def grey_material():
    m = bpy.data.materials.new("floor")
    m.use_nodes = True
    b = m.node_tree.nodes["Principled BSDF"]
    compat.principled_input(b, "Base Color").default_value = (0.35, 0.35, 0.35, 1)
    compat.principled_input(b, "Roughness").default_value = 0.7
    return m


def label(text, location, size):
    curve = bpy.data.curves.new("label", "FONT")
    curve.body = text
    curve.size = size
    curve.align_x = "CENTER"
    ob = bpy.data.objects.new("label", curve)
    bpy.context.scene.collection.objects.link(ob)
    ob.location = location
    m = bpy.data.materials.new("label")
    m.use_nodes = True
    nt = m.node_tree
    nt.nodes.clear()
    e = nt.nodes.new("ShaderNodeEmission")
    e.inputs["Color"].default_value = (1, 1, 1, 1)
    e.inputs["Strength"].default_value = 3.0
    o = nt.nodes.new("ShaderNodeOutputMaterial")
    nt.links.new(e.outputs[0], o.inputs[0])
    curve.materials.append(m)
    return ob


def instance(name, opts, random=None):
    inst = {"name": name, "random": opts.random if random is None else random}
    if opts.displacement > 0:
        inst["displacement"] = opts.displacement
    return inst


def scene_sheet(name, recipe, opts):
    scene = reset_scene()
    ctx = {"displacement": opts.displacement > 0}
    mat = materials.build_material(name, recipe, instance(name, opts), ctx)
    floor = add_mesh("plane", 6.0, (0, 0, 0))
    floor.data.materials.append(grey_material())
    s = add_mesh("sphere", 0.7, (-0.8, 0.3, 0.7))
    c = add_mesh("cube", 0.55, (0.85, -0.1, 0.55), rotation_z=0.5)
    for ob in (s, c):
        ob.data.materials.append(mat)
    add_camera((0, -4.3, 2.5), (0, 0, 0.5), lens=45)
    key = add_light("AREA", (3, -3, 4), 220, 3.0)
    aim(key, (0, 0, 0))
    fill = add_light("AREA", (-4, -2, 2), 60, 3.0)
    aim(fill, (0, 0, 0))
    sun = add_light("SUN", (0, 0, 5), 1.0, rotation=(0.6, 0.2, 0.0))
    sun.data.angle = 0.1
    label(name.replace("_", " "), (0, -1.45, 0.02), 0.22)
    return scene


def scene_tile(name, recipe, opts):
    scene = reset_scene()
    mat = materials.build_material(name, recipe, instance(name, opts), {"displacement": False})
    tile = add_mesh("plane", 1.0, (0, 0, 0))
    tile.data.materials.append(mat)
    add_camera((0, 0, 5), (0, 0, 0), ortho=2.0)
    # Flat, even light: a big emitting world and no sun, so shading does not dominate.
    scene.world.node_tree.nodes["Background"].inputs["Color"].default_value = (1, 1, 1, 1)
    scene.world.node_tree.nodes["Background"].inputs["Strength"].default_value = 1.0
    compat.set_view_look(scene.view_settings, "Standard", "None")
    return scene


def scene_check(name, recipe, opts):
    return scene_sheet(name, recipe, opts)


def scene_cost(name, recipe, opts):
    scene = reset_scene()
    mat = materials.build_material(name, recipe, instance(name, opts), {"displacement": False})
    s = add_mesh("sphere", 1.0, (0, 0, 0))
    s.data.materials.append(mat)
    add_camera((0, -4.2, 0), (0, 0, 0), lens=50)
    key = add_light("AREA", (3, -3, 3), 500, 2.0)
    aim(key, (0, 0, 0))
    return scene


def scene_density(name, recipe, opts):
    scene = reset_scene()
    mat = materials.build_material(name, recipe, instance(name, opts, 0.0), {"displacement": False})
    small = add_mesh("cube", 0.35, (-1.0, 0, 0))
    large = add_mesh("cube", 0.7, (0.8, 0, 0))
    for ob in (small, large):
        ob.data.materials.append(mat)
    add_camera((0, -10, 0), (0, 0, 0), ortho=4.0)
    scene.world.node_tree.nodes["Background"].inputs["Color"].default_value = (1, 1, 1, 1)
    compat.set_view_look(scene.view_settings, "Standard", "None")
    return scene


SCENES = {
    "sheet": scene_sheet,
    "tile": scene_tile,
    "check": scene_check,
    "cost": scene_cost,
    "density": scene_density,
}


def pink_fraction(path):
    img = bpy.data.images.load(path)
    px = img.pixels[:]
    n = len(px) // 4
    pink = 0
    for i in range(0, len(px), 4):
        r, g, b = px[i], px[i + 1], px[i + 2]
        if r > 0.9 and b > 0.9 and g < 0.1:
            pink += 1
    bpy.data.images.remove(img)
    return pink / max(n, 1)


def stripe_periods(path, scene):
    """Dominant stripe period (world units) along x on the front face of each cube, measured
    on the middle image row: 2 * span / (number of light/dark transitions)."""
    img = bpy.data.images.load(path)
    w, h = img.size
    px = img.pixels[:]
    row = h // 2
    lum = [sum(px[4 * (row * w + x) + c] for c in range(3)) / 3.0 for x in range(w)]
    bpy.data.images.remove(img)
    units_per_px = 4.0 / w  # ortho_scale / width
    out = {}
    for ob in scene.objects:
        if ob.type != "MESH":
            continue
        cx, s = ob.location.x, ob.scale.x
        lo = int((cx - 0.8 * s + 2.0) / units_per_px)
        hi = int((cx + 0.8 * s + 2.0) / units_per_px)
        seg = lum[lo:hi]
        mean = sum(seg) / max(len(seg), 1)
        bits = [v > mean for v in seg]
        flips = sum(1 for a, b in zip(bits, bits[1:]) if a != b)
        key = "small" if s < 0.5 else "large"
        out["period_" + key] = 2.0 * len(seg) * units_per_px / max(flips, 1)
        out["flips_" + key] = flips
    return out


MODES = tuple(SCENES)


def render(req, recipe, threads):
    """Build and render the scene of one `material` request; returns `file`, `timings` and
    `measures` (mode `check`: `pink`; mode `density`: stripe periods and counts)."""
    mode = req.get("mode")
    if mode not in SCENES:
        raise ValueError("unknown material mode `%s` (expected one of %s)"
                         % (mode, ", ".join(MODES)))
    name = req["name"]
    out_dir = req["out_dir"]
    if not os.path.isdir(out_dir):
        raise FileNotFoundError("output directory `%s` does not exist" % out_dir)
    size = int(req.get("size", 160))
    samples = int(req.get("samples", 16))
    t0 = time.perf_counter()
    scene = SCENES[mode](name, recipe, Options(req))
    square = mode in ("tile", "cost")
    scene.render.resolution_x = size
    scene.render.resolution_y = size if square else int(size * 0.75)
    if mode == "density":
        scene.render.resolution_y = size // 2
    scene.render.resolution_percentage = 100
    scene.cycles.samples = samples
    scene.render.threads_mode = "FIXED" if threads else "AUTO"
    if threads:
        scene.render.threads = threads
    path = os.path.join(out_dir, name + ".png")
    scene.render.filepath = path
    t1 = time.perf_counter()
    bpy.ops.render.render(write_still=True)
    t2 = time.perf_counter()
    measures = {}
    if mode == "check":
        measures["pink"] = pink_fraction(path)
    if mode == "density":
        measures.update(stripe_periods(path, scene))
    return {"file": path, "timings": {"build_s": t1 - t0, "render_s": t2 - t1},
            "measures": measures}
