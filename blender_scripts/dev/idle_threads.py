"""Per-thread CPU of a worker idling between requests, through the real protocol (issue 24).

    python3 blender_scripts/dev/idle_threads.py BLENDER MATERIALS.json SCENE.json OUT_DIR \
        [--idle 10]

BLENDER is a Blender executable or a Python with `bpy` (started as clevrtex starts it:
`render::blender::worker_command`, with CLEVRTEX_PARENT_PID set). The worker is asked for one
final render of SCENE.json (1 thread); the CPU time of each of its threads
(/proc/PID/task/*/stat: name, user and system ticks) is read over `--idle` seconds before the
render (after `ready`) and over `--idle` seconds after the reply, while the worker waits for
the next request (and, for comparison, over the render itself). A thread that keeps a core busy while the worker waits shows ~100% there
(less on a loaded machine: then its context switches per second and the system call it sits
in, from /proc, tell a spinning thread from a sleeping one).
"""

import json
import os
import subprocess
import sys
import time

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from drive import read_reply  # noqa: E402

HERE = os.path.dirname(os.path.abspath(__file__))
SCRIPTS = os.path.dirname(HERE)
TICK = os.sysconf("SC_CLK_TCK")
PID = [0]


def threads(pid):
    out = {}
    for tid in os.listdir("/proc/%d/task" % pid):
        try:
            with open("/proc/%d/task/%s/stat" % (pid, tid)) as f:
                s = f.read()
        except OSError:
            continue
        name = s[s.index("(") + 1:s.rindex(")")]
        fields = s.rsplit(")", 1)[1].split()
        out[int(tid)] = (name, int(fields[11]), int(fields[12]), _switches(pid, tid),
                         _read("/proc/%d/task/%s/syscall" % (pid, tid)).split(" ")[0],
                         _read("/proc/%d/task/%s/wchan" % (pid, tid)))
    return out


def _read(path):
    try:
        with open(path) as f:
            return f.read().strip()
    except OSError:
        return "?"


def _switches(pid, tid):
    """Voluntary + involuntary context switches of a thread so far."""
    n = 0
    for line in _read("/proc/%d/task/%s/status" % (pid, tid)).splitlines():
        if "ctxt_switches" in line:
            n += int(line.split()[1])
    return n


def report(label, before, after, seconds):
    print("%s (%.1f s, load %.2f):" % (label, seconds, os.getloadavg()[0]))
    busy = 0.0
    for tid, (name, u, s, sw, call, wchan) in sorted(after.items()):
        u0, s0, sw0 = before.get(tid, (name, 0, 0, 0))[1:4]
        du, ds = (u - u0) / TICK / seconds, (s - s0) / TICK / seconds
        busy += du + ds
        if du + ds > 0.005 or sw - sw0 > 10 * seconds:
            print("  tid %-7d %-16s user %5.1f%%  system %5.1f%%  %8.0f switches/s  "
                  "syscall %s wchan %s%s" % (tid, name, 100 * du, 100 * ds, (sw - sw0) / seconds,
                                            call, wchan, "  (main)" if tid == PID[0] else ""))
    print("  all %d threads: %.1f%% of a core" % (len(after), 100 * busy))
    return busy


def main():
    blender, mats, scene, out = sys.argv[1:5]
    idle = float(sys.argv[sys.argv.index("--idle") + 1]) if "--idle" in sys.argv else 10.0
    os.makedirs(out, exist_ok=True)
    tag = "@@clevrtex-0123456789abcdef@@"
    bridge = ["--tag", tag, "--threads", "1", "--materials", os.path.abspath(mats),
              "--device", "CPU"]
    worker = os.path.join(SCRIPTS, "worker.py")
    if os.path.basename(blender).startswith("python"):
        cmd = [blender, "-u", "-s", "-B", worker, "--"] + bridge + ["--factory-startup"]
    else:
        cmd = [blender, "-b", "--factory-startup", "--python-exit-code", "1", "--python",
               worker, "--"] + bridge
    env = dict(os.environ, CLEVRTEX_PARENT_PID=str(os.getpid()))
    log = open(os.path.join(out, "blender.log"), "w")
    proc = subprocess.Popen(cmd, stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=log,
                            env=env)

    PID[0] = proc.pid

    def reply():
        return read_reply(proc, tag)

    r = reply()
    print("ready:", r.get("blender") or r.get("version") or "")
    a = threads(proc.pid)
    time.sleep(idle)
    before = report("idle after ready", a, threads(proc.pid), idle)
    d = os.path.join(out, "final")
    os.makedirs(d, exist_ok=True)
    req = {"type": "render", "id": 1, "mode": "final", "scene": os.path.abspath(scene),
           "out_dir": d}
    a = threads(proc.pid)
    t0 = time.perf_counter()
    proc.stdin.write((json.dumps(req) + "\n").encode())
    proc.stdin.flush()
    r = reply()
    print("render reply:", r.get("type"))
    report("during the render (1 Cycles thread)", a, threads(proc.pid), time.perf_counter() - t0)
    a = threads(proc.pid)
    time.sleep(idle)
    after = report("idle after a render", a, threads(proc.pid), idle)
    proc.stdin.write(b'{"type": "quit"}\n')
    proc.stdin.flush()
    proc.wait()
    print(json.dumps({"idle_after_ready": before, "idle_after_render": after}))


if __name__ == "__main__":
    main()
