"""Whether an object's subdivided copy renders as the shape's mesh with its modifier (dev).

    blender -b --factory-startup --python-exit-code 1 \
        --python blender_scripts/dev/subdivided_copy_probe.py -- MATERIALS.json SCENE.json [...] \
        [--forms modifier,copy]
    .venv-bpy/bin/python blender_scripts/dev/subdivided_copy_probe.py -- ...   # bpy 4.5

Per scene file (rendered as it is: size, samples, passes): builds it and assigns its materials
as the worker does, so each object whose material neither displaces nor reads Generated
coordinates is its shape's subdivided copy (shapes.new_object, shading.reads_unsubdivided);
gives every such object the shape's mesh and modifier (shapes.make_final), then renders the
final render (builder.render_final, the session freed after it) once per form of `--forms`,
in order: `modifier...` as it is, `copy...` with those objects turned back into copies. Prints,
between the first and the last form, how many values of the RGB PNG's pixels and of each EXR
(`passes.exr`, `shadow.exr`) differ. `--forms modifier,modifier2` or `copy,copy2` renders one
form twice: Cycles' own run-to-run differences, to compare against.
"""

import json
import os
import sys
import tempfile

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, os.path.dirname(HERE))
sys.path.insert(0, HERE)

import bpy  # noqa: E402

import builder  # noqa: E402
import exr_dump  # noqa: E402
import materials  # noqa: E402
import shapes  # noqa: E402


def _pixels(path):
    img = bpy.data.images.load(path)
    px = list(img.pixels[:])
    bpy.data.images.remove(img)
    return px


def _channels(path):
    got = exr_dump.read(path)
    return got[-1] if isinstance(got, tuple) else got


def _differ(a, b):
    return sum(1 for x, y in zip(a, b) if x != y and not (x != x and y != y))


def main():
    argv = sys.argv[sys.argv.index("--") + 1:]
    forms = ["modifier", "copy"]
    if "--forms" in argv:
        i = argv.index("--forms")
        forms = argv[i + 1].split(",")
        del argv[i:i + 2]
    with open(argv[0]) as f:
        catalogue = json.load(f)["materials"]
    out = tempfile.mkdtemp(prefix="subdivided_copy_probe_")
    for n, path in enumerate(argv[1:]):
        spec = builder.load_scene_file(path)
        built = builder.build(spec, (path, n), 1)
        builder.assign_materials(built, catalogue, materials.build_material, True)
        copies = [(obj, o["shape"]) for obj, o in zip(built.objects, spec["objects"])
                  if obj.modifiers.get("subdivision") is None]
        for obj, shape in copies:
            shapes.make_final(obj, shape)
        files = []
        for k, form in enumerate(forms):
            if form.startswith("copy") and copies and copies[0][0].modifiers.get("subdivision"):
                for obj, shape in copies:
                    obj.modifiers.remove(obj.modifiers["subdivision"])
                    obj.data = shapes._subdivided[shape].copy()  # noqa: SLF001 (dev)
                    obj.material_slots[0].link = "OBJECT"
            d = os.path.join(out, "%d_%d_%s" % (n, k, form))
            os.makedirs(d)
            got, _ = builder.render_final(built, d)
            builder.release_render()
            files.append(got)
        first, last = files[0], files[-1]
        res = ["%d of %d objects copies" % (len(copies), len(built.objects))]
        for key in sorted(first):
            if first[key].endswith(".png"):
                a, b = _pixels(first[key]), _pixels(last[key])
            else:
                ca, cb = _channels(first[key]), _channels(last[key])
                a = [v for c in sorted(ca) for v in ca[c]]
                b = [v for c in sorted(cb) for v in cb[c]]
            res.append("%s %d of %d values differ" % (key, _differ(a, b), len(a)))
        print("%s (%s vs %s): %s" % (os.path.basename(path), forms[0], forms[-1], "; ".join(res)),
              file=sys.stderr, flush=True)


main()
