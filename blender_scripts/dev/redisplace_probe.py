"""Which changes between two renders make Cycles displace an adaptive-subdivision object again
(issue 40, item 2; dev).

    blender -b --factory-startup --python blender_scripts/dev/redisplace_probe.py -- CASE \
        | grep -E "RESULT|Computing Displacement"

One cube with adaptive subdivision and a displaced material (noise height), persistent data
on, rendered twice at 64x48, 1 sample. Between the two renders CASE changes one thing:

    same          nothing
    world:tag     a World custom property read by a VIEW_LAYER Attribute node, world tagged
    world:none    the same property, no tag (the render does not see it)
    scene:tag     the same on the Scene, scene tagged
    noattr:tag    a World tag, no material reading the property
    light:none    a light's energy
    frame:none    the frame, with an auto-refresh image sequence (black, white) in the material
    frame:set     the same through scene.frame_set
    shadowvis:other   a second, plain cube's shadow-ray visibility (`visible_shadow`) off
    shadowvis:self    the displaced cube's own shadow-ray visibility off
    shadowvis:raw     the same set through foreach_set (no RNA update), then an OBJECT tag
    lightshadow:none  the light casts no shadows (`cast_shadow` / `use_shadow`)
    samples:none      scene.cycles.samples (1 -> 2; Cycles' "Sample 1/N" says whether seen)
    samples:light     the same, and a light's energy set to its own value
    bounces:none      scene.cycles.max_bounces
    bounces:light     the same, and a light's energy set to its own value
    filter:none       scene.cycles.filter_width
    passes:none       the view layer's diffuse direct pass on

Cycles prints "Computing Displacement" for each displacement it computes; "RESULT b max red"
says whether the second render saw the switch (0.812 against 0.278).
"""

import sys
import time

import bpy

sys.path.insert(0, __import__("os").path.join(__import__("os").path.dirname(
    __import__("os").path.abspath(__file__)), ".."))
import compat  # noqa: E402

mode = sys.argv[sys.argv.index("--") + 1] if "--" in sys.argv else "same"
what, _, how = mode.partition(":")
scene = bpy.context.scene
for o in list(bpy.data.objects):
    bpy.data.objects.remove(o)
scene.render.engine = "CYCLES"
scene.cycles.feature_set = "EXPERIMENTAL"
scene.cycles.samples = 1
scene.cycles.use_denoising = False
scene.render.resolution_x, scene.render.resolution_y = 64, 48
scene.render.use_persistent_data = True
# Fine dicing, so a displacement computed again shows in the time of the second render too
# (PyPI bpy prints no status lines).
scene.cycles.dicing_rate = 0.25
bpy.ops.mesh.primitive_cube_add()
obj = bpy.context.object
obj.modifiers.new("s", "SUBSURF")
obj.cycles.use_adaptive_subdivision = True
mat = bpy.data.materials.new("m")
mat.use_nodes = True
mat.cycles.displacement_method = "DISPLACEMENT"
nt = mat.node_tree
out = nt.nodes["Material Output"]
noise = nt.nodes.new("ShaderNodeTexNoise")
disp = nt.nodes.new("ShaderNodeDisplacement")
nt.links.new(noise.outputs["Fac"], disp.inputs["Height"])
nt.links.new(disp.outputs["Displacement"], out.inputs["Displacement"])
attr = nt.nodes.new("ShaderNodeAttribute")
attr.attribute_type = "VIEW_LAYER"
attr.attribute_name = "sw"
em = nt.nodes.new("ShaderNodeEmission")
nt.links.new(attr.outputs["Fac"], em.inputs["Strength"])
nt.links.new(em.outputs["Emission"], out.inputs["Surface"])
obj.data.materials.append(mat)
cam = bpy.data.objects.new("c", bpy.data.cameras.new("c"))
scene.collection.objects.link(cam)
scene.camera = cam
cam.location = (0, -6, 0)
cam.rotation_euler = (1.5708, 0, 0)
world = bpy.data.worlds.new("w")
scene.world = world
light = bpy.data.objects.new("L", bpy.data.lights.new("L", "POINT"))
scene.collection.objects.link(light)
light.location = (0, -3, 2)
other = None
if what == "shadowvis":
    bpy.ops.mesh.primitive_cube_add(location=(0, -2.5, 1), size=0.5)
    other = bpy.context.object
if what == "noattr":
    nt.links.remove(attr.outputs["Fac"].links[0])
if what == "frame":
    for f, v in ((1, 0.0), (2, 1.0)):
        im = bpy.data.images.new("sw%d" % f, 1, 1)
        im.pixels[:] = [v, v, v, 1.0]
        im.filepath_raw = "/tmp/redisplace_sw_%04d.png" % f
        im.file_format = "PNG"
        im.save()
        bpy.data.images.remove(im)
    seq = bpy.data.images.load("/tmp/redisplace_sw_0001.png")
    seq.source = "SEQUENCE"
    tex = nt.nodes.new("ShaderNodeTexImage")
    tex.image = seq
    tex.interpolation = "Closest"
    tex.image_user.use_auto_refresh = True
    tex.image_user.frame_duration = 2
    tex.image_user.frame_start = 1
    nt.links.new(tex.outputs["Color"], em.inputs["Strength"])
holder = scene if what == "scene" else world
holder["sw"] = 0.0


def render(tag):
    t = time.perf_counter()
    bpy.ops.render.render()
    bpy.data.images["Render Result"].save_render("/tmp/redisplace_%s.exr" % tag)
    print("RESULT", tag, "time", round(time.perf_counter() - t, 3), flush=True)


render("a")
if what in ("world", "scene", "noattr"):
    holder["sw"] = 1.0
    if how == "tag":
        holder.update_tag()
elif what == "light":
    light.data.energy = 500.0
elif what == "shadowvis" and how == "raw":
    bpy.data.objects.foreach_set("visible_shadow", [o != obj for o in bpy.data.objects])
    obj.update_tag(refresh={"OBJECT"})
elif what == "shadowvis":
    compat.set_cast_shadow(obj if how == "self" else other, False)
elif what == "lightshadow":
    if hasattr(light.data, "use_shadow"):
        light.data.use_shadow = False
    else:
        light.data.cycles.cast_shadow = False
elif what == "samples":
    scene.cycles.samples = 2
    if how == "light":
        light.data.energy = light.data.energy
elif what == "bounces":
    scene.cycles.max_bounces = 0
    if how == "light":
        light.data.energy = light.data.energy
elif what == "filter":
    scene.cycles.filter_width = 0.01
elif what == "passes":
    bpy.context.view_layer.use_pass_diffuse_direct = True
elif what == "frame":
    if how == "set":
        scene.frame_set(2)
    else:
        scene.frame_current = 2
render("b")
for tag in "ab":
    im = bpy.data.images.load("/tmp/redisplace_%s.exr" % tag)
    p = im.pixels[:]
    print("RESULT", tag, "max red", round(max(p[0::4]), 3))
    bpy.data.images.remove(im)
