"""Where a small image's fixed cost goes (dev): the worker's requests replayed in one process,
every Cycles status line timed.

    blender -b --factory-startup --python-exit-code 1 -t 1 \
        --python blender_scripts/dev/fixed_cost_probe.py -- MATERIALS.json SCENE.json [...] \
        [--repeat N] [--keep-session] [--eval-first] [--no-subsurf]

For each scene file, as `generate` asks a worker: a `visibility` request (build, mask-only
render, EXR written) then a `final` request (materials, final render, files written), each
followed by the worker's `release_render` (unless `--keep-session`). Prints, per render, the
wall time before Cycles' first status line (Blender's render pipeline: the render depsgraph
built and evaluated), then the time spent under each status text (digits dropped, so
`Synchronizing object | object_01_cube` and `... | object_02_sphere` add up), and per scene
the build, materials and write times. `--eval-first` evaluates the view layer's depsgraph
before each render and times it alone (what the pre-status time would be without the
render's own depsgraph). `--no-subsurf` removes the objects' level-1 subdivision modifier
before each render (a measurement only: the renders change). Scene files are rendered as they
are (size, samples, passes): make them small with the caller's own edit (the measurement of
docs/notes/performance.md, "The fixed cost of a small image", set 32x24, 1 sample, passes
rgb and mask). Outputs go to a temporary folder.
"""

import collections
import json
import os
import re
import sys
import tempfile
import time

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, os.path.dirname(HERE))

import bpy  # noqa: E402

import builder  # noqa: E402
import materials  # noqa: E402
import phases  # noqa: E402

_report = []


def out(*args):
    print(*args, file=_report[0])


def _key(status):
    """The status text after `Scene, ViewLayer |`, object names and numbers dropped."""
    parts = [x.strip() for x in status.split("|")]
    k = next((i for i, x in enumerate(parts) if "ViewLayer" in x), None)
    msg = " | ".join(parts[k + 1:] if k is not None else parts[-1:])
    msg = re.sub(r"\| (object_\d+_\w+|backdrop|clevrtex_\w+)", "| OBJ", msg)
    msg = re.sub(r"(clevrtex_\w+|object_\d+_\w+)", "OBJ", msg)
    return re.sub(r"[\d.]+(/[\d.]+)?%?", "#", msg)


def timed_render(label, totals):
    """One render; adds its status times to `totals`; returns the pre-status wall time."""
    phases.phase_of = _key  # the probe's events carry the status text itself
    t0 = time.perf_counter()
    with phases._lock:
        phases._drain()
        phases._state["events"] = []
    bpy.ops.render.render(write_still=False)
    t1 = time.perf_counter()
    with phases._lock:
        phases._drain()
        events, phases._state["events"] = phases._state["events"], None
    marks = [(t0, 0, "(before the first status)")] + events + [(t1, 0, None)]
    per = collections.OrderedDict()
    for (ta, _, name), (tb, _, _) in zip(marks, marks[1:]):
        per[name] = per.get(name, 0.0) + (tb - ta)
    for name, s in per.items():
        totals[(label, name)] += s
    return t1 - t0, per


def main():
    argv = sys.argv[sys.argv.index("--") + 1:]
    repeat, keep, eval_first = 1, False, False
    if "--repeat" in argv:
        i = argv.index("--repeat")
        repeat = int(argv[i + 1])
        del argv[i:i + 2]
    if "--keep-session" in argv:
        argv.remove("--keep-session")
        keep = True
    no_subsurf = "--no-subsurf" in argv
    if no_subsurf:
        argv.remove("--no-subsurf")
    if "--eval-first" in argv:
        argv.remove("--eval-first")
        eval_first = True
    with open(argv[0]) as f:
        catalogue = json.load(f)["materials"]
    scenes = argv[1:] * repeat
    # Status lines go to stderr through the phases pipe; this probe's report to stdout.
    sys.stdout.flush()
    _report.append(os.fdopen(os.dup(1), "w", buffering=1))
    phases.capture(2)
    out_dir = tempfile.mkdtemp(prefix="fixed_cost_probe_")
    totals = collections.defaultdict(float)
    steps = collections.defaultdict(float)
    for n, path in enumerate(scenes):
        spec = builder.load_scene_file(path)
        t = time.perf_counter()
        built = builder.build(spec, (path, n), 1)
        steps["build"] += time.perf_counter() - t
        for mode in ("visibility", "final"):
            if mode == "final":
                t = time.perf_counter()
                builder.assign_materials(built, catalogue, materials.build_material, True)
                steps["materials"] += time.perf_counter() - t
            if no_subsurf:  # measurement only: what the shapes' level-1 subdivision costs
                for obj in built.objects:
                    mod = obj.modifiers.get("subdivision")
                    if mod is not None:
                        obj.modifiers.remove(mod)
            if eval_first:
                t = time.perf_counter()
                bpy.context.evaluated_depsgraph_get()
                steps["eval_first (%s)" % mode] += time.perf_counter() - t
            # What render_visibility / render_final do, but timed here.
            orig = builder._render
            got = {}

            def probe_render(ph=None, mode=mode):
                s, per = timed_render(mode, totals)
                got[mode] = (s, per)
                return s

            builder._render = probe_render
            t = time.perf_counter()
            try:
                if mode == "visibility":
                    builder.render_visibility(built, out_dir)
                else:
                    builder.render_final(built, out_dir)
            finally:
                builder._render = orig
            steps["%s request (render + write)" % mode] += time.perf_counter() - t
            s, per = got[mode]
            out("scene %d %-10s %.3f s: %s" % (
                n, mode, s, ", ".join("%s %.3f" % (k, v) for k, v in per.items() if v >= 0.005)))
            if not keep:
                t = time.perf_counter()
                builder.release_render()
                steps["release_render"] += time.perf_counter() - t
    out("\nTOTALS over %d scenes (wall s)" % len(scenes))
    for k, v in sorted(steps.items()):
        out("  %-40s %.3f" % (k, v))
    for (mode, name), v in sorted(totals.items(), key=lambda kv: -kv[1]):
        if v >= 0.01:
            out("  %-10s %-60s %.3f" % (mode, name, v))


main()
