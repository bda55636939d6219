# Makes a ClevrTex-convention material: DIR/<Name>.blend with node group <Name> (inputs
# Color, Random, Scale, Displacement; outputs Shader, Displacement) reading the image
# texture //textures/<Name>_COL_3K.<ext> (an 8x8 image of one sRGB colour, written here).
# Args after `--`: DIR NAME R G B [EXT] [MODE]; MODE: ok | nogroup (no node group) |
# shaderinput (an extra shader input `Coat`, which the convention cannot drive) | packed (the
# texture packed into the `.blend`, its file removed) | packedhuge (packed: a PNG whose header
# claims 16384 x 16384 pixels, a few bytes on paper).
# Used by tests/user_materials.rs; runs in Blender 3.4 and in bpy 4.5.
import sys
import bpy

args = sys.argv[sys.argv.index("--") + 1:]
d, name, r, g, b = args[0], args[1], int(args[2]), int(args[3]), int(args[4])
ext = args[5] if len(args) > 5 else "png"
mode = args[6] if len(args) > 6 else "ok"
import os
os.makedirs(os.path.join(d, "textures"), exist_ok=True)
blend = os.path.join(d, name + ".blend")
tex = os.path.join(d, "textures", "%s_COL_3K.%s" % (name, ext))
img = bpy.data.images.new(name + "_COL", 8, 8)
img.pixels = [r / 255.0, g / 255.0, b / 255.0, 1.0] * 64
img.filepath_raw = tex
img.file_format = "JPEG" if ext == "jpg" else "PNG"
img.save()
bpy.data.images.remove(img)


def sock(ng, io, kind, sname):
    if hasattr(ng, "interface"):
        return ng.interface.new_socket(sname, in_out=io, socket_type=kind)
    return (ng.inputs if io == "INPUT" else ng.outputs).new(kind, sname)


if mode != "nogroup":
    ng = bpy.data.node_groups.new(name, "ShaderNodeTree")
    for sname, kind in (("Color", "NodeSocketColor"), ("Random", "NodeSocketFloat"),
                        ("Scale", "NodeSocketFloat"), ("Displacement", "NodeSocketFloat")):
        sock(ng, "INPUT", kind, sname)
    if mode == "shaderinput":
        sock(ng, "INPUT", "NodeSocketShader", "Coat")
    sock(ng, "OUTPUT", "NodeSocketShader", "Shader")
    sock(ng, "OUTPUT", "NodeSocketVector", "Displacement")
    gi = ng.nodes.new("NodeGroupInput")
    go = ng.nodes.new("NodeGroupOutput")
    tc = ng.nodes.new("ShaderNodeTexCoord")
    mp = ng.nodes.new("ShaderNodeMapping")
    ng.links.new(tc.outputs["Object"], mp.inputs["Vector"])
    it = ng.nodes.new("ShaderNodeTexImage")
    if mode == "packedhuge":
        import struct
        import zlib

        def chunk(kind, data):
            body = kind + data
            return struct.pack(">I", len(data)) + body + struct.pack(">I", zlib.crc32(body))

        with open(tex, "wb") as f:
            f.write(b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", struct.pack(">IIBBBBB", 16384, 16384, 8, 2, 0, 0, 0))
                    + chunk(b"IDAT", b"\x78\x9c\x63\x60") + chunk(b"IEND", b""))
    it.image = bpy.data.images.load(tex, check_existing=False)
    if mode in ("packed", "packedhuge"):
        it.image.pack()
    it.image.filepath = "//textures/" + os.path.basename(tex)
    ng.links.new(mp.outputs["Vector"], it.inputs["Vector"])
    bsdf = ng.nodes.new("ShaderNodeBsdfPrincipled")
    ng.links.new(it.outputs["Color"], bsdf.inputs["Base Color"])
    ng.links.new(bsdf.outputs["BSDF"], go.inputs["Shader"])
    disp = ng.nodes.new("ShaderNodeDisplacement")
    ng.links.new(gi.outputs["Displacement"], disp.inputs["Scale"])
    ng.links.new(it.outputs["Color"], disp.inputs["Height"])
    ng.links.new(disp.outputs["Displacement"], go.inputs["Displacement"])
    ng.use_fake_user = True
bpy.ops.wm.save_as_mainfile(filepath=blend, relative_remap=True)
if mode in ("packed", "packedhuge"):
    os.remove(tex)
