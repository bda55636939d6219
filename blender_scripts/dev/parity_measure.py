"""Where a Blender version's extra noise and darkness come from (issue 24; dev only).

    blender -b --factory-startup --python-exit-code 1 \
        --python blender_scripts/dev/parity_measure.py -- \
        --materials materials.json --out OUT --tag TAG [--samples 64] [--seed 0] \
        [--size 160x120] [--threads 1] [--set KEY=VALUE ...] [--only-light NAME] \
        [--parity-off KEY,...|all] SCENE.json [SCENE.json ...]
    .venv-bpy/bin/python blender_scripts/dev/parity_measure.py --materials ... (the same)

`materials.json` is `clevrtex materials json`; scene files come from `clevrtex sample` (or a
bench run's `OUT/renders/.../scene.json`). Every scene is built as the bridge builds it
(builder.build, materials.build_material, compat's per-version parity switches),
`--parity-off`: those compat.PARITY switches off (`all`: 4.x's own defaults, as before
issue 24); rendered once at `--samples` with Cycles seed `--seed`, with the light-path passes on
(diffuse/glossy/transmission direct, indirect and colour, emission, environment), the object
index and the albedo AOV, and saved as OUT/<scene>/<TAG>.exr; OUT/<scene>/<TAG>.json holds the
Blender version, the settings that were changed and the render's wall and process CPU time.
Compare renders with `parity_compare.py` (numpy: run it with `.venv-bpy/bin/python`).

`--set KEY=VALUE` (repeatable) changes one setting after the build, to split the difference
between versions by setting (a key this Blender lacks is reported and skipped):
  light_tree=0|1          Cycles 4.0+'s light tree
  mis=0|1                 every light's multiple importance sampling
  distribution=GGX|MULTI_GGX   every principled BSDF's microfacet distribution
  blur_glossy=F           Cycles' Filter Glossy
  caustics=0|1            reflective and refractive caustics
  clamp_direct=F, clamp_indirect=F
  light_threshold=F
  pattern=NAME            sampling pattern (SOBOL_BURLEY, TABULATED_SOBOL, BLUE_NOISE, ...)
  sun_angle_scale=F       multiply the sun's angle
  sheen=0                 every principled BSDF's sheen weight 0
  coat=0|F                every principled BSDF's coat weight 0 / multiplied by F
  bump_width=F            every Bump node's Filter Width (4.4+)
  max_bounces=N, diffuse_bounces=N, glossy_bounces=N
  area_energy=F           multiply every area light's energy (not the sun)
`--only-light NAME` renders with every other light hidden (`sun`, or an area light's name
from the scene file): the noise and mean per light.
"""

import argparse
import json
import os
import sys
import time

import bpy

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, os.path.dirname(HERE))
sys.path.insert(0, HERE)

import builder  # noqa: E402
import compat  # noqa: E402
import materials  # noqa: E402
import passes  # noqa: E402

LIGHT_PATH_FLAGS = [
    "use_pass_diffuse_direct", "use_pass_diffuse_indirect", "use_pass_diffuse_color",
    "use_pass_glossy_direct", "use_pass_glossy_indirect", "use_pass_glossy_color",
    "use_pass_transmission_direct", "use_pass_transmission_indirect",
    "use_pass_transmission_color", "use_pass_emit", "use_pass_environment",
]


def parse_args():
    argv = sys.argv[sys.argv.index("--") + 1:] if "--" in sys.argv else sys.argv[1:]
    p = argparse.ArgumentParser(prog="parity_measure.py")
    p.add_argument("--materials", required=True)
    p.add_argument("--out", required=True)
    p.add_argument("--tag", required=True)
    p.add_argument("--samples", type=int, default=64)
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--size", default="160x120")
    p.add_argument("--threads", type=int, default=1)
    p.add_argument("--set", action="append", default=[], dest="sets")
    p.add_argument("--only-light", default=None)
    p.add_argument("--parity-off", default="",
                   help="compat.PARITY switches to turn off (comma-separated, `all`)")
    p.add_argument("scenes", nargs="+")
    return p.parse_args(argv)


def principled_nodes():
    trees = [m.node_tree for m in bpy.data.materials if m.node_tree is not None]
    trees += list(bpy.data.node_groups)
    for t in trees:
        for n in t.nodes:
            if n.type == "BSDF_PRINCIPLED":
                yield n


def apply_set(key, value, scene):
    c = scene.cycles
    lights = [o for o in scene.objects if o.type == "LIGHT"]
    f = float(value) if value.replace(".", "", 1).replace("-", "", 1).isdigit() else None
    if key == "light_tree":
        if not hasattr(c, "use_light_tree"):
            return "absent"
        c.use_light_tree = bool(int(value))
    elif key == "mis":
        for o in lights:
            compat.light_mis(o.data, bool(int(value)))
    elif key == "distribution":
        for n in principled_nodes():
            n.distribution = value
    elif key == "blur_glossy":
        c.blur_glossy = f
    elif key == "caustics":
        c.caustics_reflective = c.caustics_refractive = bool(int(value))
    elif key in ("clamp_direct", "clamp_indirect"):
        setattr(c, "sample_" + key, f)
    elif key == "light_threshold":
        c.light_sampling_threshold = f
    elif key == "pattern":
        c.sampling_pattern = value
    elif key == "sun_angle_scale":
        for o in lights:
            if o.data.type == "SUN":
                o.data.angle *= f
    elif key in ("sheen", "coat"):
        for n in principled_nodes():
            sock = compat.principled_input(n, "Sheen" if key == "sheen" else "Clearcoat")
            if sock is None:
                continue
            if sock.is_linked:
                return "linked"
            sock.default_value = 0.0 if f == 0 else sock.default_value * f
    elif key == "bump_width":
        trees = [m.node_tree for m in bpy.data.materials if m.node_tree] + list(bpy.data.node_groups)
        for t in trees:
            for n in t.nodes:
                if n.type == "BUMP" and "Filter Width" in n.inputs:
                    n.inputs["Filter Width"].default_value = f
    elif key in ("max_bounces", "diffuse_bounces", "glossy_bounces"):
        setattr(c, key, int(value))
    elif key == "area_energy":
        for o in lights:
            if o.data.type == "AREA":
                o.data.energy *= f
    else:
        raise SystemExit("unknown --set key `%s`" % key)
    return "ok"


def main():
    args = parse_args()
    with open(args.materials, "r", encoding="utf-8") as f:
        catalogue = json.load(f)["materials"]
    w, h = (int(v) for v in args.size.split("x"))
    if compat.is_module():
        compat.factory_startup()
    for path in args.scenes:
        name = os.path.basename(os.path.dirname(path)) if os.path.basename(path) == "scene.json" \
            else os.path.basename(path).rsplit(".", 1)[0]
        spec = builder.load_scene_file(path)
        spec["render"]["width"], spec["render"]["height"] = w, h
        spec["render"]["samples"] = args.samples
        spec["render"]["cycles_seed"] = args.seed
        spec["render"].pop("adaptive_threshold", None)
        for k in [k for k in args.parity_off.split(",") if k]:
            for key in (compat.PARITY if k == "all" else [k]):
                compat.PARITY[key] = False
        built = builder.build(spec, (name,), args.threads)
        builder.assign_materials(built, catalogue, materials.build_material, displacement=True)
        scene = bpy.context.scene
        vl = bpy.context.view_layer
        passes.enable(vl, ["albedo", "mask"])
        for flag in LIGHT_PATH_FLAGS:
            setattr(vl, flag, True)
        done = {}
        for s in args.sets:
            k, v = s.split("=", 1)
            done[s] = apply_set(k, v, scene)
        if args.only_light:
            for o in scene.objects:
                if o.type == "LIGHT":
                    o.hide_render = o.name != args.only_light
        d = os.path.join(args.out, name)
        os.makedirs(d, exist_ok=True)
        t0, c0 = time.perf_counter(), sum(os.times()[:2])
        bpy.ops.render.render(write_still=False)
        wall, cpu = time.perf_counter() - t0, sum(os.times()[:2]) - c0
        builder._save(os.path.join(d, args.tag + ".exr"), "EXR")
        info = {"blender": compat.version_string(), "tag": args.tag, "samples": args.samples,
                "seed": args.seed, "sets": done, "only_light": args.only_light,
                "parity": compat.parity_settings(),
                "wall_s": wall, "cpu_s": cpu, "load": os.getloadavg()[0]}
        with open(os.path.join(d, args.tag + ".json"), "w") as f:
            json.dump(info, f, indent=1)
        print("%s %s %s: %.2f s wall, %.2f s cpu %s" % (compat.version_string(), name, args.tag,
                                                       wall, cpu, done), flush=True)


main()
