"""Which setting leaves a bpy worker's TBB thread spinning after a render (issue 24; dev).

    .venv-bpy/bin/python blender_scripts/dev/spin_probe.py MATERIALS.json SCENE.json \
        [--persistent 0|1] [--free 0|1] [--idle 5]

Builds SCENE.json as the bridge does (1 Cycles thread), renders it once, then sleeps `--idle`
seconds and prints each thread's CPU and context switches over that sleep (from /proc): a
thread that spins in sched_yield shows tens of thousands of switches per second.
`--persistent 0` turns Cycles' persistent data off; `--free 1` keeps it for the render and
then turns it off and on again, which frees the kept Cycles session (what the worker does
after each request).
"""

import json
import os
import sys
import time

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, os.path.dirname(HERE))

import bpy  # noqa: E402

import builder  # noqa: E402
import compat  # noqa: E402
import materials  # noqa: E402


def threads():
    out = {}
    for tid in os.listdir("/proc/self/task"):
        try:
            with open("/proc/self/task/%s/stat" % tid) as f:
                fields = f.read().rsplit(")", 1)[1].split()
            with open("/proc/self/task/%s/status" % tid) as f:
                sw = sum(int(line.split()[1]) for line in f if "ctxt_switches" in line)
        except OSError:
            continue
        out[tid] = (int(fields[11]) + int(fields[12]), sw)
    return out


def main():
    args = sys.argv[1:]
    opt = {"--persistent": "1", "--idle": "5", "--free": "0"}
    for k in list(opt):
        if k in args:
            i = args.index(k)
            opt[k] = args[i + 1]
            del args[i:i + 2]
    mats, scene_path = args
    compat.factory_startup()
    with open(mats) as f:
        catalogue = json.load(f)["materials"]
    spec = builder.load_scene_file(scene_path)
    built = builder.build(spec, ("probe",), 1)
    builder.assign_materials(built, catalogue, materials.build_material, displacement=True)
    bpy.context.scene.render.use_persistent_data = opt["--persistent"] == "1"
    bpy.ops.render.render(write_still=False)
    if opt["--free"] == "1":
        # What the worker does after each request (builder.release_render): turning the
        # setting off frees Cycles' kept session (Blender's update of the property).
        bpy.context.scene.render.use_persistent_data = False
        bpy.context.scene.render.use_persistent_data = True
    idle = float(opt["--idle"])
    a = threads()
    time.sleep(idle)
    b = threads()
    tick = os.sysconf("SC_CLK_TCK")
    worst = max(((b[t][1] - a.get(t, (0, 0))[1]) / idle, (b[t][0] - a.get(t, (0, 0))[0]) / tick
                 / idle, t) for t in b)
    print("SPIN persistent=%s free=%s: busiest thread %s: %.0f switches/s, %.1f%% of a core "
          "(load %.1f)" % (opt["--persistent"], opt["--free"], worst[2], worst[0], 100 * worst[1],
                           os.getloadavg()[0]), flush=True)


main()
