"""Regenerate `blender_scripts/teapot_mesh.json` from a Blender that bundles the "extra
objects" add-on (Debian's 3.4.1):

    blender -b --factory-startup --python blender_scripts/dev/dump_teapot.py

The teapot module is loaded on its own (the whole add-on does not enable headless in Debian's
build: another of its modules needs numpy).
"""

import importlib.util
import json
import os

import addon_utils

HERE = os.path.dirname(os.path.abspath(__file__))
OUT = os.path.join(HERE, "..", "teapot_mesh.json")

for root in addon_utils.paths():
    path = os.path.join(root, "add_mesh_extra_objects", "add_mesh_teapot.py")
    if os.path.isfile(path):
        spec = importlib.util.spec_from_file_location("clevrtex_extra_teapot", path)
        module = importlib.util.module_from_spec(spec)
        spec.loader.exec_module(module)
        break
else:
    raise SystemExit("no `add_mesh_extra_objects` add-on in %s" % addon_utils.paths())

verts, faces = module.make_teapot("1", 6)
with open(OUT, "w", encoding="utf-8") as f:
    json.dump({"verts": [list(v) for v in verts], "faces": [list(fc) for fc in faces]}, f,
              separators=(",", ":"))
print("wrote %s: %d vertices, %d faces" % (OUT, len(verts), len(faces)))
