"""Shadow-pass quality and cost of candidate methods, against a 256-spp reference (dev only).

    blender -b --factory-startup --python-exit-code 1 \
        --python blender_scripts/dev/shadow_measure.py -- \
        --materials materials.json --out OUT [--size 160x120] [--threads 2] \
        [--methods noshadow-8,paired-8,...] [--floor SCENE.json] \
        [--filter-width 0.01] [--white-only-passes] [--second-ref] [--reuse-refs] \
        [--pattern SOBOL] SCENE.json [SCENE.json ...]

`materials.json` is `clevrtex materials json`; scene files come from `clevrtex sample`.
`--floor SCENE.json` adds that scene with its objects removed: a lit open floor where the
shadow pass should be 0 everywhere (reported as its maximum and 99.9th percentile).

For every scene: the final render at the scene's samples (64 for every variant), then the
references, then each candidate method, all at `--size` (scene files are 320x240). A method
gives the direct light with object shadows (`lit`) and without (`un`); the shadow is
`1 - lum(lit) / lum(un)` with lit/un = diffuse direct * diffuse colour + glossy direct *
glossy colour (the colours of the `lit` render), clamped, quantised to 8 bits: the bridge's
formula up to 0.9, and the same as today's (`DiffDir` alone) for the white methods, whose
colours are 1 and glossy light 0. Reference: textured methods are compared with the textured
pair at `--ref-samples` (256) per render, white methods with the white pair; both use
another seed (7919) than every candidate, so their noise is independent of the candidates'.
`--no-textured-ref` skips the textured reference; `--ref-samples 0` skips both (timings).
The shadow is undefined (0) where `un` is under max(1e-4, 1% of its 99th percentile), as in
`post::shadow_undefined_below`.

White methods (and the white references) take these options:
  --filter-width W     Cycles' pixel filter width of their renders; 0.01 (what the bridge
                       uses, builder.SHADOW_FILTER_WIDTH): every sample through
                       the pixel's centre. Default: the scene's (anti-aliased).
  --white-only-passes  their renders enable only the pass's `DiffDir`, as the bridge does
                       (for timings); by default they also write mask, depth, normal, colours.
  --single-ref         white references from one render each (`white-single-N`, see
                       below) instead of the pair (`white-paired-N`).
  --second-ref         a second white reference with another seed (`ref2-white-paired-N_*`):
                       the RMSE between the two is the reference's own noise.
  --reuse-refs         white references already in OUT are read, not rendered again.
  --pattern P          Cycles' sampling pattern of the candidates (not the references).
  --no-light-tree      Cycles 4.0+'s light tree off in every render (references too).
  --white-light-tree   white renders keep the scene's light tree; by default they turn it
                       off, as the bridge does (builder.SHADOW_LIGHT_TREE).
Every render's EXR stays in OUT/<scene>/ (`white-paired-16_lit.exr`...), for
`cargo run --release -p clevrtex-render --example shadow_filter_measure -- OUT METHOD...`.

Methods (N = samples of each extra render):
  noshadow-N  the bridge up to 0.9: lit from the final render, un from a direct-light-only
              render (max_bounces 0) at N spp with objects casting no shadows.
  paired-N    lit and un both from direct-light-only renders at N spp with the same Cycles
              seed: the two renders trace the same rays and pick the same light samples, so
              they differ only where an object blocks a shadow ray.
  adaptiveT-N paired, with Cycles' adaptive sampling (noise threshold T, at most N spp) in
              both renders: where no object shadows, both stop at the same sample.
              `adaptiveT_mK-N`: at least K samples (Cycles still takes 16 before its first
              check).
  fast-N      paired, but the backdrop casts no shadow in `lit` and `un` traces no shadow
              ray at all (every light's shadows off).
  white-M     method M with every material's surface replaced by a white diffuse BSDF
              (displacement kept; builder.WhiteSurfaces): the shadow of the direct
              irradiance, no texture or glossy noise, cheaper shading. Compared with the
              white reference. `white-paired-16` with `--filter-width 0.01` is what the
              bridge does at 64 samples (builder.default_shadow_samples).
  nobd-M      method M with the backdrop casting no shadows (its relief then shadows it in
              neither render; shadow rays skip its dense displaced mesh).
  perlight-N  paired, one pair of renders per light (the others hidden), N spp each: no
              light-selection noise.
  single-N    (as `white-single-N`) one render instead of the pair: builder.OneRenderShadow
              (objects transparent to shadow rays in red only, lights white): red is the
              light without object shadows, green with; what the bridge does now.
  catcher-N   one direct-light-only render at N spp with the floor as Cycles' shadow catcher
              and a transparent film: shadow = 1 - lum(Shadow Catcher pass) (floor only).

Reported per scene and method: RMSE of the shadow against the reference, the open floor's
maximum, and the extra render time (wall and process CPU seconds; CPU is less disturbed by
other processes on a shared machine) over the final render's. Results go to OUT/results.json
and a table on stdout. Uses `exr_dump.py` (beside this file) to read the EXRs, because
Debian's Blender has no numpy.
"""

import argparse
import json
import math
import os
import sys
import time

import bpy

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, os.path.dirname(HERE))
sys.path.insert(0, HERE)

import builder  # noqa: E402
import compat  # noqa: E402
import exr_dump  # noqa: E402
import materials  # noqa: E402
import passes  # noqa: E402

REF_SAMPLES = 256
REF_SEED = 7919
REF_SEED_2 = 104729
DEFAULT_METHODS = "noshadow-8,noshadow-16,noshadow-64,paired-4,paired-8,paired-16,catcher-8"


def parse_args():
    argv = sys.argv[sys.argv.index("--") + 1:] if "--" in sys.argv else []
    p = argparse.ArgumentParser(prog="shadow_measure.py")
    p.add_argument("--materials", required=True)
    p.add_argument("--out", required=True)
    p.add_argument("--size", default="160x120")
    p.add_argument("--threads", type=int, default=0)
    p.add_argument("--methods", default=DEFAULT_METHODS)
    p.add_argument("--ref-samples", type=int, default=REF_SAMPLES,
                   help="samples per render of the references; 0: no reference (timing only)")
    p.add_argument("--floor", default=None)
    p.add_argument("--white-only-passes", action="store_true",
                   help="white methods' renders enable only the shadow pass's DiffDir, as the "
                        "bridge does (timings); the default adds mask/depth/normal/colours")
    p.add_argument("--filter-width", type=float, default=None,
                   help="Cycles' pixel filter width of the white methods' renders (and white "
                        "references); 0.01: every sample through the pixel's centre")
    p.add_argument("--pattern", default=None,
                   help="Cycles' sampling pattern of the white candidates (not the references)")
    p.add_argument("--no-light-tree", action="store_true",
                   help="Cycles 4.0+'s light tree off for every render (scene `render.light_tree`)")
    p.add_argument("--white-light-tree", action="store_true",
                   help="white renders keep the scene's light tree (4.0+) instead of turning it "
                        "off as the bridge does (builder.SHADOW_LIGHT_TREE)")
    p.add_argument("--reuse-refs", action="store_true",
                   help="white references already in OUT (same settings) are read, not rendered")
    p.add_argument("--single-ref", action="store_true",
                   help="white references from one render each (white-single-N, the bridge's "
                        "method now) instead of the pair")
    p.add_argument("--second-ref", action="store_true",
                   help="also a second white reference with another seed (REF_SEED_2), saved as "
                        "ref2-white-paired-N_{lit,un}.exr: the reference's own noise")
    p.add_argument("--no-textured-ref", action="store_true",
                   help="skip the textured reference (only white methods compared)")
    p.add_argument("scenes", nargs="*")
    return p.parse_args(argv)


def cpu_s():
    t = os.times()
    return t.user + t.system


def timed_render():
    w0, c0 = time.perf_counter(), cpu_s()
    bpy.ops.render.render(write_still=False)
    return time.perf_counter() - w0, cpu_s() - c0


def enable_light_passes(view_layer):
    """The light and colour passes every method here reads (more than the bridge's shadow
    pass needs since 0.10: the textured methods weigh diffuse and glossy light by colour)."""
    # Mask, depth and normal too: the Rust shadow filter's guides (`shadow_filter_measure`).
    passes.enable(view_layer, ["albedo", "mask", "depth", "normal"])
    for flag in ("use_pass_diffuse_direct", "use_pass_diffuse_color",
                 "use_pass_glossy_direct", "use_pass_glossy_color"):
        setattr(view_layer, flag, True)


def render_final(path):
    enable_light_passes(bpy.context.view_layer)
    t = timed_render()
    builder._save(path, "EXR")
    return t


def set_light_shadows(enabled):
    """Whether every light traces shadow rays (`cycles.cast_shadow` up to 3.x, `use_shadow`)."""
    for o in bpy.context.scene.objects:
        if o.type == "LIGHT":
            if hasattr(o.data, "cycles") and hasattr(o.data.cycles, "cast_shadow"):
                o.data.cycles.cast_shadow = enabled
            else:
                o.data.use_shadow = enabled


WHITE_ONLY_PASSES = [False]
FILTER_WIDTH = [None]
REUSE_REFS = [0]
PATTERN = [None]
WHITE_LIGHT_TREE = [False]


def render_direct(built, path, samples, cast, seed=None, catcher=False, only_light=None,
                  adaptive=None, light_shadows=True, min_samples=0):
    """Direct light only (max_bounces 0), `samples` spp, objects casting shadows or not;
    `adaptive`: Cycles' adaptive sampling with this noise threshold (`samples` the most)."""
    scene = bpy.context.scene
    lights = [o for o in scene.objects if o.type == "LIGHT"]
    if only_light is not None:
        for o in lights:
            o.hide_render = o.name != only_light
    vl = bpy.context.view_layer
    if WHITE_ONLY_PASSES[0]:
        passes.enable(vl, ["shadow"])
    else:
        enable_light_passes(vl)
    if os.environ.get("SHADOW_MEASURE_SAMPLE_COUNT"):
        vl.cycles.pass_debug_sample_count = adaptive is not None
    set_light_shadows(light_shadows)
    c = scene.cycles
    saved = (c.samples, c.max_bounces, c.use_adaptive_sampling, c.seed,
             scene.render.film_transparent)
    c.samples = samples
    c.max_bounces = 0
    c.use_adaptive_sampling = adaptive is not None
    if adaptive is not None:
        c.adaptive_threshold = adaptive
        c.adaptive_min_samples = min_samples
    if seed is not None:
        c.seed = seed
    for obj in built.objects:
        compat.set_cast_shadow(obj, cast)
    if catcher:
        built.backdrop.is_shadow_catcher = True
        scene.render.film_transparent = True
        vl.cycles.use_pass_shadow_catcher = True
    try:
        t = timed_render()
    finally:
        c.samples, c.max_bounces, c.use_adaptive_sampling, c.seed, \
            scene.render.film_transparent = saved
        for obj in built.objects:
            compat.set_cast_shadow(obj, True)
        for o in lights:
            o.hide_render = False
        set_light_shadows(True)
        if catcher:
            built.backdrop.is_shadow_catcher = False
            vl.cycles.use_pass_shadow_catcher = False
    builder._save(path, "EXR")
    return t


def lum(r, g, b):
    return 0.2126 * r + 0.7152 * g + 0.0722 * b


def direct_light(data, colours):
    """Per-pixel luminance of diffuse direct * colour + glossy direct * colour."""
    n = len(data["ViewLayer.DiffDir.R"])

    def ch(d, layer, c, default):
        # White methods rendered with --white-only-passes have DiffDir alone.
        return d.get("ViewLayer.%s.%s" % (layer, c), [default] * n)
    out = []
    for c in "RGB":
        dd, gd = ch(data, "DiffDir", c, 0.0), ch(data, "GlossDir", c, 0.0)
        dc, gc = ch(colours, "DiffCol", c, 1.0), ch(colours, "GlossCol", c, 1.0)
        out.append([dd[i] * dc[i] + gd[i] * gc[i] for i in range(len(dd))])
    return [lum(out[0][i], out[1][i], out[2][i]) for i in range(len(out[0]))]


def shadow(lit_path, un_path):
    """The bridge's shadow (post::encode_shadow), as 8-bit values / 255; colours from `lit`."""
    _, _, lit = exr_dump.read(lit_path)
    _, _, un = exr_dump.read(un_path)
    ll, uu = direct_light(lit, lit), direct_light(un, lit)
    eps = undefined_below(uu)
    out = []
    for l, u in zip(ll, uu):
        if not (math.isfinite(l) and math.isfinite(u)) or u < eps:
            out.append(0.0)
        else:
            out.append(round(min(1.0, max(0.0, 1.0 - l / u)) * 255.0) / 255.0)
    return out


def undefined_below(uu):
    """post::shadow_undefined_below: max(1e-4, 1% of the 99th percentile of the lit pixels)."""
    lit = sorted(u for u in uu if math.isfinite(u) and u >= 1e-4)
    if not lit:
        return 1e-4
    return max(1e-4, 0.01 * lit[int(round((len(lit) - 1) * 0.99))])


def single_shadow(path):
    """The shadow from one OneRenderShadow render: 1 - green / red of `DiffDir`."""
    _, _, d = exr_dump.read(path)
    ll, uu = d["ViewLayer.DiffDir.G"], d["ViewLayer.DiffDir.R"]
    eps = undefined_below(uu)
    return [0.0 if not (math.isfinite(l) and math.isfinite(u)) or u < eps
            else round(min(1.0, max(0.0, 1.0 - l / u)) * 255.0) / 255.0
            for l, u in zip(ll, uu)]


def catcher_shadow(path):
    _, _, d = exr_dump.read(path)
    ch = [d["ViewLayer.Shadow Catcher.%s" % c] for c in "RGB"]
    return [round(min(1.0, max(0.0, 1.0 - lum(r, g, b))) * 255.0) / 255.0
            for r, g, b in zip(*ch)]


def rmse(a, b):
    return math.sqrt(sum((x - y) ** 2 for x, y in zip(a, b)) / len(a))


def quantile(vals, q):
    s = sorted(vals)
    return s[min(len(s) - 1, int(q * len(s)))]


def add(a, b):
    return (a[0] + b[0], a[1] + b[1])


def shadow_sum(pairs):
    """Shadow from per-light (lit, un) EXR pairs: sums of the direct light over lights."""
    ll = uu = None
    for lit_path, un_path in pairs:
        _, _, lit = exr_dump.read(lit_path)
        _, _, un = exr_dump.read(un_path)
        l, u = direct_light(lit, lit), direct_light(un, lit)
        ll = l if ll is None else [a + b for a, b in zip(ll, l)]
        uu = u if uu is None else [a + b for a, b in zip(uu, u)]
    eps = undefined_below(uu)
    return [0.0 if u < eps else round(min(1.0, max(0.0, 1.0 - l / u)) * 255.0) / 255.0
            for l, u in zip(ll, uu)]


def run_method(built, method, d, final_exr, seed=None, tag=""):
    kind, n = method.rsplit("-", 1)
    n = int(n)
    if kind.startswith("white-"):
        c = bpy.context.scene.cycles
        saved = c.filter_width
        saved_pattern = c.sampling_pattern
        saved_tree = getattr(c, "use_light_tree", None)
        if saved_tree is not None and not WHITE_LIGHT_TREE[0]:
            c.use_light_tree = builder.SHADOW_LIGHT_TREE
        if FILTER_WIDTH[0] is not None:
            c.filter_width = FILTER_WIDTH[0]
        if PATTERN[0] is not None and seed is None:
            c.sampling_pattern = PATTERN[0]
        try:
            ctx = (builder.OneRenderShadow(built) if method.startswith("white-single-")
                   else builder.WhiteSurfaces(built))
            with ctx:
                return run_method(built, method[len("white-"):], d, final_exr, seed,
                                  tag + "white-")
        finally:
            c.filter_width = saved
            c.sampling_pattern = saved_pattern
            if saved_tree is not None:
                c.use_light_tree = saved_tree
    method = tag + method
    un = os.path.join(d, "%s_un.exr" % method)
    if kind.startswith("nobd-"):
        compat.set_cast_shadow(built.backdrop, False)
        try:
            return run_method(built, method[len("nobd-"):], d, final_exr, seed, tag + "nobd-")
        finally:
            compat.set_cast_shadow(built.backdrop, True)
    if kind.startswith("adaptive"):
        # adaptiveT-N or adaptiveT_mK-N: threshold T, at most N, at least K (0: Cycles' auto).
        spec = kind[len("adaptive"):]
        thr, mins = (spec.split("_m") + ["0"])[:2]
        thr, mins = float(thr), int(mins)
        lit = os.path.join(d, "%s_lit.exr" % method)
        t1 = render_direct(built, lit, n, cast=True, seed=seed, adaptive=thr, min_samples=mins)
        t2 = render_direct(built, un, n, cast=False, seed=seed, adaptive=thr, min_samples=mins)
        return shadow(lit, un), add(t1, t2)
    if kind == "perlight":
        pairs, t = [], (0.0, 0.0)
        for light in [o.name for o in bpy.context.scene.objects if o.type == "LIGHT"]:
            lit = os.path.join(d, "%s_%s_lit.exr" % (method, light))
            unl = os.path.join(d, "%s_%s_un.exr" % (method, light))
            t = add(t, render_direct(built, lit, n, cast=True, seed=seed, only_light=light))
            t = add(t, render_direct(built, unl, n, cast=False, seed=seed, only_light=light))
            pairs.append((lit, unl))
        return shadow_sum(pairs), t
    if kind == "noshadow":
        t = render_direct(built, un, n, cast=False)
        return shadow(final_exr, un), t
    if kind == "paired":
        lit = os.path.join(d, "%s_lit.exr" % method)
        if REUSE_REFS[0] and n == REUSE_REFS[0] and os.path.exists(lit) and os.path.exists(un):
            return shadow(lit, un), (0.0, 0.0)
        t1 = render_direct(built, lit, n, cast=True, seed=seed)
        t2 = render_direct(built, un, n, cast=False, seed=seed)
        return shadow(lit, un), (t1[0] + t2[0], t1[1] + t2[1])
    if kind == "fast":
        # The backdrop casts no shadow in `lit`; `un` traces no shadow ray at all.
        lit = os.path.join(d, "%s_lit.exr" % method)
        compat.set_cast_shadow(built.backdrop, False)
        try:
            t1 = render_direct(built, lit, n, cast=True, seed=seed)
        finally:
            compat.set_cast_shadow(built.backdrop, True)
        t2 = render_direct(built, un, n, cast=False, seed=seed, light_shadows=False)
        return shadow(lit, un), add(t1, t2)
    if kind == "single":
        # builder.OneRenderShadow: red = without object shadows, green = with.
        path = os.path.join(d, "%s.exr" % method)
        if REUSE_REFS[0] and n == REUSE_REFS[0] and os.path.exists(path):
            return single_shadow(path), (0.0, 0.0)
        c = bpy.context.scene.cycles
        saved_tb = c.transparent_max_bounces
        c.transparent_max_bounces = builder.SHADOW_TRANSPARENT_BOUNCES
        try:
            t = render_direct(built, path, n, cast=True, seed=seed)
        finally:
            c.transparent_max_bounces = saved_tb
        return single_shadow(path), t
    if kind == "catcher":
        t = render_direct(built, un, n, cast=True, catcher=True)
        return catcher_shadow(un), t
    raise SystemExit("unknown method `%s`" % method)


def main():
    args = parse_args()
    WHITE_ONLY_PASSES[0] = args.white_only_passes
    FILTER_WIDTH[0] = args.filter_width
    PATTERN[0] = args.pattern
    WHITE_LIGHT_TREE[0] = args.white_light_tree
    if args.reuse_refs:
        REUSE_REFS[0] = args.ref_samples
    os.makedirs(args.out, exist_ok=True)
    with open(args.materials, "r", encoding="utf-8") as f:
        catalogue = json.load(f)["materials"]
    w, h = (int(v) for v in args.size.split("x"))
    methods = [m for m in args.methods.split(",") if m]
    jobs = [(os.path.basename(s).rsplit(".", 1)[0], s, False) for s in args.scenes]
    if args.floor:
        jobs.append(("open_floor", args.floor, True))
    results = []
    for name, path, open_floor in jobs:
        spec = builder.load_scene_file(path)
        if open_floor:
            spec["objects"] = []
        spec["render"]["width"], spec["render"]["height"] = w, h
        d = os.path.join(args.out, name)
        os.makedirs(d, exist_ok=True)
        if args.no_light_tree:
            spec["render"]["light_tree"] = False
        built = builder.build(spec, (name,), args.threads)
        builder.assign_materials(built, catalogue, materials.build_material, displacement=True)
        final_exr = os.path.join(d, "final.exr")
        t_final = render_final(final_exr)
        row = {"scene": name, "open_floor": open_floor, "final_samples": spec["render"]["samples"],
               "final_wall_s": t_final[0], "final_cpu_s": t_final[1], "methods": {}}
        ref = None
        if not args.no_textured_ref and args.ref_samples > 0:
            ref_lit, ref_un = os.path.join(d, "ref_lit.exr"), os.path.join(d, "ref_un.exr")
            render_direct(built, ref_lit, args.ref_samples, cast=True, seed=REF_SEED)
            render_direct(built, ref_un, args.ref_samples, cast=False, seed=REF_SEED)
            ref = shadow(ref_lit, ref_un)
            # How far the final render's direct light (full bounces, MIS) is from the
            # direct-only render's, on pixels lit in both: the lit term's bias between methods.
            _, _, fin = exr_dump.read(final_exr)
            _, _, rl = exr_dump.read(ref_lit)
            lf, lr = direct_light(fin, fin), direct_light(rl, fin)
            lit_px = [(a, b) for a, b in zip(lf, lr) if b > 1e-3]
            row["final_over_direct_lit"] = (sum(a for a, _ in lit_px)
                                            / max(1e-9, sum(b for _, b in lit_px)))
        white_ref = None
        if any(m.startswith("white-") for m in methods) and args.ref_samples > 0:
            ref_method = "white-%s-%d" % ("single" if args.single_ref else "paired",
                                          args.ref_samples)
            white_ref, _ = run_method(built, ref_method, d, final_exr, seed=REF_SEED)
            if args.second_ref:
                ref2, _ = run_method(built, ref_method,
                                     d, final_exr, seed=REF_SEED_2, tag="ref2-")
                row["white_ref_vs_ref2"] = rmse(white_ref, ref2)
                print("%-28s white reference vs second reference: rmse %.4f"
                      % (name, row["white_ref_vs_ref2"]), flush=True)
        for m in methods:
            s, t = run_method(built, m, d, final_exr)
            row["methods"][m] = {
                "rmse": (lambda r: rmse(s, r) if r else float("nan"))(
                    white_ref if m.startswith("white-") else ref),
                "rmse_textured_ref": rmse(s, ref) if ref else float("nan"),
                "max": max(s), "p999": quantile(s, 0.999),
                "extra_wall": t[0] / t_final[0], "extra_cpu": t[1] / t_final[1],
                "wall_s": t[0], "cpu_s": t[1],
            }
            print("%-28s %-18s rmse %.4f (vs textured ref %.4f) max %.3f p99.9 %.3f "
                  "extra wall %5.1f%% cpu %5.1f%%"
                  % (name, m, row["methods"][m]["rmse"], row["methods"][m]["rmse_textured_ref"],
                     max(s), row["methods"][m]["p999"],
                     100 * t[0] / t_final[0], 100 * t[1] / t_final[1]), flush=True)
        print("%-28s final %.1f s wall %.1f s cpu; final/direct lit %.4f"
              % (name, t_final[0], t_final[1], row.get("final_over_direct_lit", float("nan"))),
              flush=True)
        results.append(row)
        with open(os.path.join(args.out, "results.json"), "w") as f:
            json.dump(results, f, indent=1)
    print("\nmethod        mean RMSE  worst RMSE  open-floor max  extra wall  extra cpu")
    for m in methods:
        scenes = [r for r in results if not r["open_floor"]]
        floor = [r for r in results if r["open_floor"]]
        rm = [r["methods"][m]["rmse"] for r in scenes] or [float("nan")]
        ew = [r["methods"][m]["extra_wall"] for r in results]
        ec = [r["methods"][m]["extra_cpu"] for r in results]
        print("%-12s  %9.4f  %10.4f  %14s  %9.1f%%  %8.1f%%" % (
            m, sum(rm) / len(rm), max(rm),
            "%.3f" % floor[0]["methods"][m]["max"] if floor else "-",
            100 * sum(ew) / len(ew), 100 * sum(ec) / len(ec)))


if __name__ == "__main__":
    main()
