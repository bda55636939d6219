"""Builds catalogue materials as Cycles node trees.

PLACEHOLDER until the material issue lands: every material is a principled BSDF whose colour
is derived from the material name. The interface is final:

    build_material(name, recipe, instance, context) -> bpy.types.Material

- name: catalogue name;
- recipe: the material's entry of materials.json (see docs/bridge-protocol.md), as a dict;
- instance: the scene file's MaterialInstance as a dict (random, color, displacement, scale);
- context: {"displacement": bool} -- False for the cheap visibility pass, where no
  displacement or adaptive subdivision may be set up.
"""

import hashlib

import bpy


def build_material(name, recipe, instance, context):
    mat = bpy.data.materials.new(name)
    mat.use_nodes = True
    bsdf = mat.node_tree.nodes["Principled BSDF"]
    color = instance.get("color")
    if color is None:
        h = hashlib.sha256(name.encode()).digest()
        color = [h[0] / 255.0, h[1] / 255.0, h[2] / 255.0]
    bsdf.inputs["Base Color"].default_value = (color[0], color[1], color[2], 1.0)
    return mat
