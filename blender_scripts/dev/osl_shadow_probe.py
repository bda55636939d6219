"""Probe (dev only): the shadow pass from one pixel-centre sample with an OSL shader that
traces its own shadow rays to stratified points of every light (Blender builds with OSL:
PyPI's bpy; Debian's 3.4.1 has none).

    .venv-bpy/bin/python blender_scripts/dev/osl_shadow_probe.py -- --materials M.json \
        --out OUT [--size 320x240] [--threads 2] [--n 4] SCENE.json [...]

Per scene: the 64-spp final render (timed; `--no-final` skips it), then the OSL render
(1 spp, pixel centre; the surface emits (L, L0, 0): the luminance of the direct light on a
white diffuse surface with and without object shadows, the backdrop shadowing both; Cycles'
OSL back end ignores AOV outputs), twice (the second shows the cost without compiling).
Writes OUT/<scene>/osl.exr (`Combined.R` = L, `Combined.G` = L0) and prints the times.
Measured once (docs/notes/performance.md, "Shadow pass": ~3.3 s of compilation per scene); a
probe, not validated against the Cycles reference.
"""

import argparse
import math
import os
import sys
import time

import bpy

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, os.path.dirname(HERE))
sys.path.insert(0, HERE)

import builder  # noqa: E402
import materials  # noqa: E402
import passes  # noqa: E402

OSL = r"""
// Generated per scene. n x n stratified samples per light.
float lum(color c) { return 0.2126 * c[0] + 0.7152 * c[1] + 0.0722 * c[2]; }

shader clevrtex_shadow(output float L = 0.0, output float L0 = 0.0)
{
    int n = %(n)d;
    float l = 0.0, l0 = 0.0;
    point Px = P;
    normal Nn = normalize(N);
    %(lights)s
    L = l;
    L0 = l0;
}
"""

# One light: visibility of sample point q (area) or direction (sun) with weight w.
AREA = r"""
    {
        point c = point(%(c)s); vector ex = vector(%(ex)s); vector ey = vector(%(ey)s);
        vector nl = vector(%(nl)s); float k = %(k).9g;
        for (int i = 0; i < n; i++) for (int j = 0; j < n; j++) {
            float u = (i + hashnoise(Px, float(%(seed)d + 2 * (i * n + j)))) / n - 0.5;
            float v = (j + hashnoise(Px, float(%(seed)d + 2 * (i * n + j)) + 1)) / n - 0.5;
            point q = c + u * ex + v * ey;
            vector d = q - Px;
            float r = length(d);
            d /= r;
            float cx = dot(Nn, d);
            float cy = -dot(d, nl);
            if (cx > 0.0 && cy > 0.0) {
                float w = k * cx * cy / (r * r);
                %(visible)s
            }
        }
    }
"""

SUN = r"""
    {
        vector z = vector(%(z)s); vector ax = vector(%(ax)s); vector ay = vector(%(ay)s);
        float k = %(k).9g; float cmax = %(cmax).9g;
        for (int i = 0; i < n; i++) for (int j = 0; j < n; j++) {
            float a = (i + hashnoise(Px, float(%(seed)d + 2 * (i * n + j)))) / n;
            float b = (j + hashnoise(Px, float(%(seed)d + 2 * (i * n + j)) + 1)) / n;
            float ct = 1.0 - a * (1.0 - cmax);
            float st = sqrt(max(0.0, 1.0 - ct * ct));
            float ph = 2.0 * M_PI * b;
            vector d = ct * z + st * (cos(ph) * ax + sin(ph) * ay);
            float cx = dot(Nn, d);
            float r = 1.0e4;
            if (cx > 0.0) {
                float w = k * cx;
                %(visible)s
            }
        }
    }
"""

# First hit along the segment: the backdrop (index 0) shadows both; an object shadows `L`
# only, unless the backdrop is further along (then both).
VISIBLE = r"""
                if (!trace(Px, d, "maxdist", r)) { l += w; l0 += w; }
                else {
                    float idx = 0.0;
                    getmessage("trace", "object:index", idx);
                    if (idx > 0.5) {
                        float t = 0.0;
                        getmessage("trace", "hitdist", t);
                        point h = Px + t * d;
                        int back = 0;
                        for (int s = 0; s < 8; s++) {
                            if (!trace(h, d, "mindist", 1e-4, "maxdist", r - t)) break;
                            float i2 = 0.0; float t2 = 0.0;
                            getmessage("trace", "object:index", i2);
                            getmessage("trace", "hitdist", t2);
                            if (i2 < 0.5) { back = 1; break; }
                            h = h + (t2 + 1e-4) * d;
                            t = t + t2 + 1e-4;
                        }
                        if (!back) l0 += w;
                    }
                }
"""


def vec(v):
    return ", ".join("%.9g" % x for x in v)


def norm(v):
    n = math.sqrt(sum(x * x for x in v))
    return [x / n for x in v]


def cross(a, b):
    return [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]]


def lum(c):
    return 0.2126 * c[0] + 0.7152 * c[1] + 0.0722 * c[2]


def osl_source(spec, n):
    parts = []
    for i, light in enumerate(spec["lights"]):
        m = light["matrix_world"]
        col = lambda j: [m[0][j], m[1][j], m[2][j]]  # noqa: E731
        s = light["size"]
        ex, ey = [x * s for x in norm(col(0))], [x * s for x in norm(col(1))]
        nl = [-x for x in norm(col(2))]
        # Cycles 3.x: an area light of power E lights like a point light of E / (4 pi) W/sr.
        k = light["energy"] * lum(light["color"]) / (4.0 * math.pi) / (n * n)
        parts.append(AREA % {"c": vec(col(3)), "ex": vec(ex), "ey": vec(ey), "nl": vec(nl),
                             "k": k, "seed": 100 * i, "visible": VISIBLE})
    sun = spec["sun"]
    z = norm([-x for x in sun["direction"]])
    ax = norm(cross(z, [0.0, 0.0, 1.0] if abs(z[2]) < 0.9 else [1.0, 0.0, 0.0]))
    ay = cross(z, ax)
    parts.append(SUN % {"z": vec(z), "ax": vec(ax), "ay": vec(ay),
                        "k": sun["strength"] / (n * n), "cmax": math.cos(sun["angle"] / 2.0),
                        "seed": 1000, "visible": VISIBLE})
    return OSL % {"n": n, "lights": "\n".join(parts)}


def setup_osl(built, path):
    # PyPI's bpy keeps `oslquery` (the add-on reads the compiled shader's parameters with it)
    # in its own bundled site-packages.
    cand = os.path.join(bpy.utils.resource_path("LOCAL"), "python", "lib",
                        "python%d.%d" % sys.version_info[:2], "site-packages")
    if os.path.isdir(cand) and cand not in sys.path:
        sys.path.append(cand)
    from cycles import osl as cosl
    scene = bpy.context.scene
    scene.cycles.shading_system = True
    vl = bpy.context.view_layer
    for name in ("L", "L0"):
        if name not in vl.aovs:
            a = vl.aovs.add()
            a.name = name
            a.type = "VALUE"
    mats = set()
    for obj in [built.backdrop] + built.objects:
        for slot in obj.material_slots:
            if slot.material is not None:
                mats.add(slot.material)
    for mat in mats:
        nt = mat.node_tree
        out = next(n for n in nt.nodes if n.type == "OUTPUT_MATERIAL" and n.is_active_output)
        # Cycles' OSL back end ignores AOV outputs: the two values leave as the emission of
        # the surface (R = L, G = L0), read from the Combined pass of a 1-spp render.
        script = nt.nodes.new("ShaderNodeScript")
        script.mode = "EXTERNAL"
        script.filepath = path
        cosl.update_script_node(script, lambda *a: None)
        comb = nt.nodes.new("ShaderNodeCombineColor")
        nt.links.new(script.outputs["L"], comb.inputs[0])
        nt.links.new(script.outputs["L0"], comb.inputs[1])
        emit = nt.nodes.new("ShaderNodeEmission")
        emit.inputs["Strength"].default_value = 1.0
        nt.links.new(comb.outputs[0], emit.inputs["Color"])
        nt.links.new(emit.outputs["Emission"], out.inputs["Surface"])


def timed():
    t = os.times()
    w0, c0 = time.perf_counter(), t.user + t.system
    bpy.ops.render.render(write_still=False)
    t = os.times()
    return time.perf_counter() - w0, t.user + t.system - c0


def main():
    argv = sys.argv[sys.argv.index("--") + 1:] if "--" in sys.argv else []
    p = argparse.ArgumentParser()
    p.add_argument("--materials", required=True)
    p.add_argument("--out", required=True)
    p.add_argument("--size", default="320x240")
    p.add_argument("--threads", type=int, default=2)
    p.add_argument("--n", type=int, default=4)
    p.add_argument("--no-final", action="store_true")
    p.add_argument("scenes", nargs="+")
    args = p.parse_args(argv)
    import json
    with open(args.materials) as f:
        catalogue = json.load(f)["materials"]
    w, h = (int(v) for v in args.size.split("x"))
    for path in args.scenes:
        name = os.path.basename(path).rsplit(".", 1)[0]
        d = os.path.join(args.out, name)
        os.makedirs(d, exist_ok=True)
        spec = builder.load_scene_file(path)
        spec["render"]["width"], spec["render"]["height"] = w, h
        built = builder.build(spec, (name,), args.threads)
        builder.assign_materials(built, catalogue, materials.build_material, displacement=True)
        passes.enable(bpy.context.view_layer, ["rgb", "mask", "depth", "normal", "albedo"])
        tf = (float("nan"), float("nan")) if args.no_final else timed()
        src = os.path.join(d, "shadow.osl")
        with open(src, "w") as f:
            f.write(osl_source(spec, args.n))
        t0 = time.perf_counter()
        setup_osl(built, src)
        t_setup = time.perf_counter() - t0
        passes.enable(bpy.context.view_layer, ["mask"])
        c = bpy.context.scene.cycles
        c.samples = 1
        c.max_bounces = 0
        c.filter_width = 0.01
        c.use_adaptive_sampling = False
        t1 = timed()
        t2 = timed()
        builder._save(os.path.join(d, "osl.exr"), "EXR")
        print("%s final %.2f s wall %.2f cpu | osl setup %.2f s, render 1 %.2f wall %.2f cpu"
              " (%.1f%%), render 2 %.2f wall %.2f cpu (%.1f%%)"
              % (name, tf[0], tf[1], t_setup, t1[0], t1[1], 100 * t1[1] / tf[1],
                 t2[0], t2[1], 100 * t2[1] / tf[1]), flush=True)


if __name__ == "__main__":
    main()
