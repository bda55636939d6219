"""Builds one scene file into Blender's current scene, and renders it.

No randomness here: every pose comes from the scene file (docs/bridge-protocol.md and
crates/scene/src/scene_file.rs). A worker builds many scenes in turn; `clear()` removes
everything the previous scene made except the cached shape meshes.
"""

import json
import os
import time

import bpy
from bpy_extras.object_utils import world_to_camera_view
from mathutils import Matrix, Vector

import compat
import passes
import shapes
from shading import assign_materials, material_displaces  # noqa: F401

SCENE_FORMAT = "clevrtex-scene"
SCENE_VERSION = 1

# The shadow pass: one direct-light-only render (no bounces) in which every surface is a
# white diffuse BSDF (displacement kept, so the geometry is the final render's), the lights
# are white (power scaled by their colour's luminance), and objects are transparent to shadow
# rays in red only (OneRenderShadow): its direct light `DiffDir` is, per pixel, the light
# without object shadows in red and with them in green, both from the same camera ray and
# light samples, so they differ only where an object blocks a light sample, and Rust computes
# shadow = 1 - green / red (clevrtex_render::post::encode_shadow). Every sample of a pixel
# goes through the pixel's centre (SHADOW_FILTER_WIDTH): the pass is the shadow of the one
# surface point there, like the mask and depth, so there is no anti-aliasing noise (which
# surface a sample hits) on silhouettes and shadow edges, and all the samples go to the
# light (Cycles 4.0+'s light tree off: SHADOW_LIGHT_TREE). Samples: the request's
# `shadow_samples`, else the scene file's `render.shadow_samples`, else three eighths of the
# scene's samples (24 at the default 64), at most SHADOW_SAMPLES_MAX.
# Measured with blender_scripts/dev/shadow_measure.py against the same render at 256 spp
# with another seed, at 320x240 (docs/notes/performance.md, "Shadow pass"): RMSE 0.0083
# (0.0074-0.0091 over five scenes) at 24, 0.0104 at 16, 0.018 at 8; an open floor exactly 0;
# extra time at 24 over the 64-spp final render: 6-7% on `full` scenes with a flat floor,
# 20% with a displaced one, 22-29% on `clevr` (a direct-light sample costs about the same
# everywhere, and `clevr`'s final render is cheap). Before this the pass took two renders
# (with and without object shadows, same seed): the same noise per sample at ~1.6x the time;
# before that, anti-aliased pairs (RMSE 0.025 at 8 samples with a 3x3 filter) and, up to
# 0.9, the textured final render against an 8-spp no-shadow render (~0.1, up to 0.6 on an
# open floor).
SHADOW_SAMPLES_MAX = 64
# Cycles' pixel filter width of the shadow render: its smallest (Cycles clamps to 0.01 px),
# i.e. every sample through the pixel's centre.
SHADOW_FILTER_WIDTH = 0.01
# Cycles 4.0+'s light tree in the shadow render: off, whatever the scene asks for the final
# render. Measured on bpy 4.5 with the two renders the pass took before
# (docs/notes/performance.md, "Shadow pass"): with the tree, RMSE 0.034 at 16 samples on
# `clevr_000000` and `full_000000`; without, 0.0110 / 0.0099, as on 3.4.1 (which has no
# tree). The light with and without object shadows shares its light samples either way (an
# open floor is 0); the tree only spends them worse on this question.
SHADOW_LIGHT_TREE = False
# Transparent bounces of a shadow ray in the one shadow render (OneRenderShadow): objects are
# transparent to it, and every object it crosses costs two or more; past the limit Cycles
# counts the ray as blocked in every channel.
SHADOW_TRANSPARENT_BOUNCES = 128


def default_shadow_samples(samples):
    """Samples of the shadow render for a final render of `samples`: three eighths."""
    return max(1, min(SHADOW_SAMPLES_MAX, (3 * samples + 7) // 8))

# Cycles seed: fixed, so two renders of one scene are identical (and visibility's single
# sample is the final render's first sample).
CYCLES_SEED = 0

BACKDROP_STEP = 0.2  # metres between profile samples of the backdrop mesh
BACKDROP_Y_STEP = 1.0  # metres between sweep samples along y


def load_scene_file(path):
    with open(path, "r", encoding="utf-8") as f:
        scene = json.load(f)
    if scene.get("format") != SCENE_FORMAT:
        raise ValueError("`%s` is not a scene file (format is `%s`)" % (path, scene.get("format")))
    if scene.get("version") != SCENE_VERSION:
        raise ValueError(
            "scene file `%s` has version %s, this bridge reads version %d"
            % (path, scene.get("version"), SCENE_VERSION)
        )
    for obj in scene["objects"]:
        if obj["shape"] not in shapes.SHAPES:
            raise ValueError("unknown shape `%s` in `%s`" % (obj["shape"], path))
    for name in scene["passes"]:
        if name not in passes.PASSES:
            raise ValueError("unknown pass `%s` in `%s`" % (name, path))
    return scene


def _matrix(rows):
    return Matrix([list(r) for r in rows])


# --- clearing ----------------------------------------------------------------------------


def clear():
    """Remove every object, camera, light, world and material, and orphaned data blocks.

    Kept: the cached shape meshes, and anything with a fake user (the shared material trees,
    and node groups or images the materials module caches across scenes).
    """
    for obj in list(bpy.data.objects):
        bpy.data.objects.remove(obj, do_unlink=True)
    keep = set(m.name for m in shapes.cached_meshes())
    for me in list(bpy.data.meshes):
        if me.name not in keep:
            bpy.data.meshes.remove(me)
    for coll in (bpy.data.cameras, bpy.data.lights, bpy.data.materials, bpy.data.worlds):
        for block in list(coll):
            if not block.use_fake_user:  # the shared material trees (assign_materials)
                coll.remove(block)
    # Orphans left by materials (node groups, textures, images) unless protected.
    for _ in range(3):
        removed = 0
        for coll in (bpy.data.node_groups, bpy.data.textures, bpy.data.images):
            for block in list(coll):
                if block.users == 0 and not block.use_fake_user:
                    coll.remove(block)
                    removed += 1
        if not removed:
            break


# --- building ----------------------------------------------------------------------------


def _pchip_slopes(xs, ys):
    """Monotone cubic (Fritsch-Carlson) tangents: smooth, and never overshoots the profile."""
    n = len(xs)
    h = [xs[i + 1] - xs[i] for i in range(n - 1)]
    d = [(ys[i + 1] - ys[i]) / h[i] for i in range(n - 1)]
    m = [0.0] * n
    m[0], m[-1] = d[0], d[-1]
    for i in range(1, n - 1):
        if d[i - 1] * d[i] <= 0.0:
            m[i] = 0.0
        else:
            w1, w2 = 2.0 * h[i] + h[i - 1], h[i] + 2.0 * h[i - 1]
            m[i] = (w1 + w2) / (w1 / d[i - 1] + w2 / d[i])
    return m


def _sample_profile(profile):
    xs = [p[0] for p in profile]
    ys = [p[1] for p in profile]
    if len(xs) < 2 or any(xs[i + 1] <= xs[i] for i in range(len(xs) - 1)):
        raise ValueError("backdrop profile needs at least two points with increasing x")
    m = _pchip_slopes(xs, ys)
    out = []
    for i in range(len(xs) - 1):
        h = xs[i + 1] - xs[i]
        steps = max(1, int(round(h / BACKDROP_STEP)))
        for s in range(steps):
            t = s / steps
            h00 = 2 * t ** 3 - 3 * t ** 2 + 1
            h10 = t ** 3 - 2 * t ** 2 + t
            h01 = -2 * t ** 3 + 3 * t ** 2
            h11 = t ** 3 - t ** 2
            y = h00 * ys[i] + h10 * h * m[i] + h01 * ys[i + 1] + h11 * h * m[i + 1]
            out.append((xs[i] + t * h, y))
    out.append((xs[-1], ys[-1]))
    return out


def _build_backdrop(spec, collection):
    pts = _sample_profile(spec["profile"])
    y0, y1 = spec["y_range"]
    ny = max(1, int(round((y1 - y0) / BACKDROP_Y_STEP)))
    ys = [y0 + (y1 - y0) * j / ny for j in range(ny + 1)]
    verts = [(x, y, z) for (x, z) in pts for y in ys]
    faces = []
    cols = ny + 1
    for i in range(len(pts) - 1):
        for j in range(ny):
            a = i * cols + j
            # Counter-clockwise seen from above / in front: normals face the scene (+z on the floor).
            faces.append((a, a + cols, a + cols + 1, a + 1))
    me = bpy.data.meshes.new("clevrtex_backdrop")
    me.from_pydata(verts, [], faces)
    # Metric UVs: u = arc length along the profile, v = y, both in metres.
    arc = [0.0]
    for i in range(1, len(pts)):
        dx, dz = pts[i][0] - pts[i - 1][0], pts[i][1] - pts[i - 1][1]
        arc.append(arc[-1] + (dx * dx + dz * dz) ** 0.5)
    uv = me.uv_layers.new(name="UVMap")
    for poly in me.polygons:
        for li in poly.loop_indices:
            vi = me.loops[li].vertex_index
            uv.data[li].uv = (arc[vi // cols], ys[vi % cols] - y0)
    compat.shade_smooth(me)
    me.materials.append(None)
    me.update()
    obj = bpy.data.objects.new("backdrop", me)
    obj.rotation_euler = (0.0, 0.0, spec["rotation_z"])
    obj.pass_index = 0
    obj.material_slots[0].link = "OBJECT"
    collection.objects.link(obj)
    return obj


def _build_camera(spec, scene, collection):
    cam = bpy.data.cameras.new("camera")
    cam.type = "PERSP"
    cam.lens_unit = "MILLIMETERS"
    cam.lens = spec["focal_length_mm"]
    cam.sensor_fit = "AUTO"
    cam.sensor_width = spec["sensor_width_mm"]
    cam.clip_start = spec["clip_start"]
    cam.clip_end = spec["clip_end"]
    obj = bpy.data.objects.new("camera", cam)
    collection.objects.link(obj)
    obj.matrix_world = _matrix(spec["matrix_world"])
    scene.camera = obj
    return obj


def _build_lights(scene_spec, collection):
    out = []
    for spec in scene_spec["lights"]:
        light = bpy.data.lights.new(spec["name"], "AREA")
        light.shape = "SQUARE"
        light.size = spec["size"]
        light.energy = compat.area_light_energy(spec["energy"])
        light.color = spec["color"]
        obj = bpy.data.objects.new(spec["name"], light)
        collection.objects.link(obj)
        obj.matrix_world = _matrix(spec["matrix_world"])
        out.append(obj)
    sun_spec = scene_spec["sun"]
    sun = bpy.data.lights.new("sun", "SUN")
    sun.energy = compat.sun_strength(sun_spec["strength"])
    sun.angle = sun_spec["angle"]
    obj = bpy.data.objects.new("sun", sun)
    collection.objects.link(obj)
    obj.matrix_world = _matrix(sun_spec["matrix_world"])
    out.append(obj)
    return out


def _build_world(scene):
    world = bpy.data.worlds.new("black")
    world.use_nodes = True
    bg = world.node_tree.nodes.get("Background")
    bg.inputs["Color"].default_value = (0.0, 0.0, 0.0, 1.0)
    bg.inputs["Strength"].default_value = 0.0
    world.color = (0.0, 0.0, 0.0)
    scene.world = world


def apply_render_settings(scene, spec, threads):
    r = spec["render"]
    scene.render.engine = "CYCLES"
    compat.apply_device(scene)
    scene.render.resolution_x = r["width"]
    scene.render.resolution_y = r["height"]
    scene.render.resolution_percentage = 100
    scene.render.pixel_aspect_x = 1.0
    scene.render.pixel_aspect_y = 1.0
    scene.render.film_transparent = False
    scene.render.use_compositing = False
    scene.render.use_sequencer = False
    # Keep Cycles' session and synced scene between renders and requests (the worker frees it
    # when idle: release_render). Pixels are identical with and without (checked). The shadow
    # render still computes displacement again: its material edits update every object that
    # uses them, and Cycles re-tessellates an object with adaptive subdivision on any update
    # (so do a change of passes and of any `scene.render` setting; a VIEW_LAYER attribute
    # switch is re-read by 3.4 only after a scene tag, which does the same).
    scene.render.use_persistent_data = True
    scene.render.dither_intensity = 0.0
    # No metadata (date, render time, file name...) in the files: identical renders give
    # byte-identical files.
    for prop in scene.render.bl_rna.properties:
        if prop.identifier.startswith("use_stamp"):
            setattr(scene.render, prop.identifier, False)
    if threads > 0:
        scene.render.threads_mode = "FIXED"
        scene.render.threads = threads
    else:
        scene.render.threads_mode = "AUTO"
    # The experimental feature set (adaptive subdivision, up to 4.5) always, displaced or
    # not: flipping it between scenes made Cycles start a new session (SessionParams).
    # Without adaptive subdivision on an object it changes nothing in the render.
    compat.set_experimental_features(scene, True)
    c = scene.cycles
    c.samples = r["samples"]
    c.use_adaptive_sampling = r.get("adaptive_threshold") is not None
    if c.use_adaptive_sampling:
        c.adaptive_threshold = r["adaptive_threshold"]
    c.max_bounces = r["max_bounces"]
    c.diffuse_bounces = r["diffuse_bounces"]
    c.glossy_bounces = r["glossy_bounces"]
    c.transmission_bounces = r["transmission_bounces"]
    c.transparent_max_bounces = r["transparent_max_bounces"]
    c.sample_clamp_indirect = r.get("clamp_indirect", 0.0)
    c.sample_clamp_direct = 0.0
    c.pixel_filter_type = "BLACKMAN_HARRIS"
    c.filter_width = r["filter_width"]
    c.blur_glossy = r["blur_glossy"]
    c.use_denoising = False
    c.use_preview_denoising = False
    compat.apply_levers(c, r)
    c.seed = r.get("cycles_seed", CYCLES_SEED)
    c.use_animated_seed = False
    c.time_limit = 0.0
    compat.set_color_management(
        scene, r["view_transform"], r["look"], r["exposure"], r["gamma"]
    )
    # No frame_set()/view_layer.update(): evaluating the viewport depsgraph (subdivision
    # modifiers) cost ~0.25 s per scene and the render builds its own depsgraph anyway.
    scene.frame_current = 1


class BuiltScene:
    """The Blender objects of one scene file, plus the materials currently assigned."""

    def __init__(self, spec, key):
        self.spec = spec
        self.key = key
        self.backdrop = None
        self.objects = []
        self.camera = None
        self.material_context = None
        self.build_s = 0.0


def build(spec, key, threads):
    t0 = time.perf_counter()
    clear()
    # Before anything else is in the scene: it evaluates the view layer (shapes.subdivide).
    shapes.subdivide(o["shape"] for o in spec["objects"])
    scene = bpy.context.scene
    collection = scene.collection
    built = BuiltScene(spec, key)
    _build_world(scene)
    built.camera = _build_camera(spec["camera"], scene, collection)
    _build_lights(spec, collection)
    built.backdrop = _build_backdrop(spec["backdrop"], collection)
    for i, ospec in enumerate(spec["objects"]):
        obj = shapes.new_object(ospec["shape"], "object_%02d_%s" % (i + 1, ospec["shape"]),
                                collection)
        s = ospec["scale"]
        obj.scale = (s, s, s)
        obj.rotation_euler = (0.0, 0.0, ospec["rotation_deg"] * 3.141592653589793 / 180.0)
        obj.location = ospec["location"]
        obj.pass_index = i + 1
        built.objects.append(obj)
    apply_render_settings(scene, spec, threads)
    built.build_s = time.perf_counter() - t0
    return built


# --- rendering ---------------------------------------------------------------------------


def release_render():
    """Free the Cycles session that persistent data keeps after a render (the worker calls
    this when no request came for worker.IDLE_RELEASE_S, and after a failure). Kept idle, it
    leaves one of the TBB worker threads of PyPI's bpy 4.5
    spinning in sched_yield (measured: ~28000 context switches a second, a whole core when the
    machine is otherwise idle, mostly kernel time) and one of bpy 5.0's busy at 100% while the
    worker waits for its next request; freed, none (blender_scripts/dev/spin_probe.py,
    docs/notes/performance.md "Blender 3.4, 4.5 and 5.0 at parity"). Turning the setting off frees
    the session (Blender's update of the property); it is turned on again for the next
    request, whose shadow render reuses its final render's synced geometry."""
    r = bpy.context.scene.render
    if r.use_persistent_data:
        r.use_persistent_data = False
        r.use_persistent_data = True


def _save(path, fmt):
    scene = bpy.context.scene
    if fmt == "PNG":
        compat.set_png_output(scene.render.image_settings, compression=15)
    else:
        # RLE: lossless and as fast as no compression (ZIP took 0.1 s per file, RLE 0.016 s).
        compat.set_exr_multilayer_output(scene.render.image_settings, "RLE")
    bpy.data.images["Render Result"].save_render(path, scene=scene)


def _render(ph=None):
    """One render; its time split into phases on `ph` (phases.Phases) when given."""
    t0 = time.perf_counter()
    if ph is None:
        bpy.ops.render.render(write_still=False)
    else:
        ph.render(lambda: bpy.ops.render.render(write_still=False))
    return time.perf_counter() - t0


def _write(ph, fn):
    w0, c0 = time.perf_counter(), time.process_time()
    fn()
    if ph is not None:
        ph.add("write", time.perf_counter() - w0, time.process_time() - c0)


def data_block_counts():
    """How many data blocks of each kind exist: constant across scenes, or something leaks."""
    kinds = ("objects", "meshes", "materials", "lights", "cameras", "worlds", "node_groups",
             "images", "textures")
    return {k: len(getattr(bpy.data, k)) for k in kinds}


def projected(built):
    """Object origins through Blender's camera: [x right, y down, depth] in pixels/metres."""
    scene = bpy.context.scene
    w, h = scene.render.resolution_x, scene.render.resolution_y
    out = []
    # From the scene file's locations, not obj.matrix_world, which is only valid after a
    # depsgraph update that the build skips on purpose.
    for ospec in built.spec["objects"]:
        co = world_to_camera_view(scene, built.camera, Vector(ospec["location"]))
        out.append([co.x * w, (1.0 - co.y) * h, co.z])
    return out


def render_visibility(built, out_dir, ph=None):
    scene = bpy.context.scene
    view_layer = bpy.context.view_layer
    passes.enable(view_layer, ["mask"])
    c = scene.cycles
    saved = (c.samples, c.max_bounces, c.use_adaptive_sampling)
    c.samples = 1
    c.max_bounces = 0
    c.use_adaptive_sampling = False
    try:
        render_s = _render(ph)
    finally:
        c.samples, c.max_bounces, c.use_adaptive_sampling = saved
    t0 = time.perf_counter()
    path = os.path.join(out_dir, "visibility.exr")
    _write(ph, lambda: _save(path, "EXR"))
    return {"visibility": path}, {"render_s": render_s, "write_s": time.perf_counter() - t0}


def render_final(built, out_dir, shadow_samples=None, ph=None):
    scene = bpy.context.scene
    view_layer = bpy.context.view_layer
    wanted = list(built.spec["passes"])
    passes.enable(view_layer, passes.final_passes(wanted))
    cpu0 = time.process_time()
    timings = {"render_s": _render(ph)}
    # CPU seconds of every thread of this process during the render (Cycles' threads, and any
    # other thread that ran meanwhile): what `bench render` compares across Blenders, steadier
    # than the wall time on a loaded machine.
    timings["render_cpu_s"] = time.process_time() - cpu0
    files = {}
    t0 = time.perf_counter()
    if "rgb" in wanted:
        files["rgb"] = os.path.join(out_dir, "rgb.png")
        _write(ph, lambda: _save(files["rgb"], "PNG"))
    if any(p in wanted for p in passes.EXR_PASSES):
        files["passes"] = os.path.join(out_dir, "passes.exr")
        _write(ph, lambda: _save(files["passes"], "EXR"))
    timings["write_s"] = time.perf_counter() - t0
    if "shadow" in wanted:
        samples = (shadow_samples or built.spec["render"].get("shadow_samples")
                   or default_shadow_samples(scene.cycles.samples))
        shadow_files, timings["shadow_render_s"], write_s = _render_shadow(
            built, out_dir, samples, ph)
        files.update(shadow_files)
        timings["write_s"] += write_s
    return files, timings


class WhiteSurfaces:
    """Within `with`: every material of `built` shows a white diffuse BSDF instead of its
    surface, and keeps its displacement (the geometry stays the final render's; checked:
    identical first-sample depth on the displaced `full8.json` floor). Restored on exit."""

    def __init__(self, built):
        mats = set()
        for obj in [built.backdrop] + built.objects:
            for slot in obj.material_slots:
                if slot.material is not None and slot.material.use_nodes:
                    mats.add(slot.material)
        self.materials = sorted(mats, key=lambda m: m.name)
        self.swapped = []

    def __enter__(self):
        for mat in self.materials:
            nt = mat.node_tree
            out = next((n for n in nt.nodes
                        if n.type == "OUTPUT_MATERIAL" and n.is_active_output), None)
            if out is None:
                continue
            sock = out.inputs["Surface"]
            old = sock.links[0].from_socket if sock.is_linked else None
            node = nt.nodes.new("ShaderNodeBsdfDiffuse")
            node.inputs["Color"].default_value = (1.0, 1.0, 1.0, 1.0)
            nt.links.new(node.outputs["BSDF"], sock)
            self.swapped.append((nt, sock, old, node))
        return self

    def __exit__(self, *exc):
        for nt, sock, old, node in reversed(self.swapped):
            nt.nodes.remove(node)
            if old is not None:
                nt.links.new(old, sock)
        self.swapped = []
        return False


class OneRenderShadow:
    """Within `with`: the shadow pass's light with and without object shadows come out of
    ONE render, in two colour channels of its light. Every surface is white diffuse to
    camera rays (displacement kept, as WhiteSurfaces); to shadow rays the objects
    (pass_index > 0) are a transparent BSDF of colour (1, 0, 0), the backdrop stays opaque:
    a shadow ray an object blocks carries its light in red only. Every light is made white,
    its power scaled by the luminance of its colour, so each channel of the direct light is
    the luminance the pass uses: red = without object shadows, green = with. Both channels
    come from the same camera ray and light sample, so they differ exactly where an object
    blocks a sample. The lights' multiple importance sampling is off: a BSDF-sampled ray
    that reaches a light counts in both channels even where an object stands in the way of
    the red one (seen as 0.1% of the pixels with one sample), so the light comes from light
    samples alone (unbiased either way). Restored on exit."""

    def __init__(self, built):
        self.surfaces = WhiteSurfaces(built)
        self.added = []
        self.lights = []

    def __enter__(self):
        self.surfaces.__enter__()
        for nt, sock, _old, diffuse in self.surfaces.swapped:
            n = nt.nodes.new
            transparent = n("ShaderNodeBsdfTransparent")
            transparent.inputs["Color"].default_value = (1.0, 0.0, 0.0, 1.0)
            path = n("ShaderNodeLightPath")
            info = n("ShaderNodeObjectInfo")
            is_object = n("ShaderNodeMath")
            is_object.operation = "GREATER_THAN"
            is_object.inputs[1].default_value = 0.5
            fac = n("ShaderNodeMath")
            fac.operation = "MULTIPLY"
            mix = n("ShaderNodeMixShader")
            nt.links.new(info.outputs["Object Index"], is_object.inputs[0])
            nt.links.new(path.outputs["Is Shadow Ray"], fac.inputs[0])
            nt.links.new(is_object.outputs["Value"], fac.inputs[1])
            nt.links.new(fac.outputs["Value"], mix.inputs["Fac"])
            nt.links.new(diffuse.outputs["BSDF"], mix.inputs[1])
            nt.links.new(transparent.outputs["BSDF"], mix.inputs[2])
            nt.links.new(mix.outputs["Shader"], sock)
            self.added.append((nt, [transparent, path, info, is_object, fac, mix]))
        for obj in bpy.context.scene.objects:
            if obj.type == "LIGHT":
                light = obj.data
                c = tuple(light.color)
                mis = compat.light_mis(light, False)
                self.lights.append((light, c, light.energy, mis))
                light.energy = light.energy * (0.2126 * c[0] + 0.7152 * c[1] + 0.0722 * c[2])
                light.color = (1.0, 1.0, 1.0)
        return self

    def __exit__(self, *exc):
        for light, c, energy, mis in self.lights:
            light.color, light.energy = c, energy
            compat.light_mis(light, mis)
        self.lights = []
        for nt, nodes in self.added:
            for node in nodes:
                nt.nodes.remove(node)
        self.added = []
        # WhiteSurfaces relinks the material's own surface (removing the diffuse).
        return self.surfaces.__exit__(*exc)


def _render_shadow(built, out_dir, samples, ph=None):
    """The shadow pass's render (see the comment above SHADOW_SAMPLES_MAX): direct light on
    white surfaces, `samples` samples, every one through the pixel's centre, objects
    transparent to shadow rays in red (OneRenderShadow). Returns (files, render seconds,
    write seconds)."""
    scene = bpy.context.scene
    passes.enable(bpy.context.view_layer, ["shadow"])
    c = scene.cycles
    saved = (c.samples, c.max_bounces, c.use_adaptive_sampling, c.filter_width,
             c.transparent_max_bounces)
    c.samples = max(1, samples)
    c.max_bounces = 0
    c.filter_width = SHADOW_FILTER_WIDTH
    c.transparent_max_bounces = SHADOW_TRANSPARENT_BOUNCES
    # Adaptive sampling would stop where the unshadowed light (red) has converged.
    c.use_adaptive_sampling = False
    # Cycles 4.0+'s light tree off (SHADOW_LIGHT_TREE): with it the pass was 3x noisier.
    light_tree = getattr(c, "use_light_tree", None)
    if light_tree is not None:
        c.use_light_tree = SHADOW_LIGHT_TREE
    try:
        with OneRenderShadow(built):
            render_s = _render(ph)
        t0 = time.perf_counter()
        path = os.path.join(out_dir, "shadow.exr")
        _write(ph, lambda: _save(path, "EXR"))
        write_s = time.perf_counter() - t0
    finally:
        (c.samples, c.max_bounces, c.use_adaptive_sampling, c.filter_width,
         c.transparent_max_bounces) = saved
        if light_tree is not None:
            c.use_light_tree = light_tree
    return {"shadow": path}, render_s, write_s
