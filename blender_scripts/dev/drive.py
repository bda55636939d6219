"""Development driver: starts one worker and sends it render requests (plain python3).

    python3 blender_scripts/dev/drive.py OUT_DIR MODE:SCENE.json [MODE:SCENE.json ...]

MODE is `visibility`, `final` or `both`; `bad:` sends a request for a missing scene, to see
the error reply. Prints every reply line and the wall time of each request; Blender's own
chatter goes to OUT_DIR/blender.log.
"""

import json
import os
import subprocess
import sys
import time

HERE = os.path.dirname(os.path.abspath(__file__))
SCRIPTS = os.path.dirname(HERE)


def cpu_seconds(pid):
    """User + system CPU time of the worker so far: unlike wall time, not inflated when other
    processes compete for the cores."""
    with open("/proc/%d/stat" % pid) as f:
        fields = f.read().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def read_reply(proc, tag, echo_other=False):
    """The next reply line of the worker `proc` (its JSON), skipping other stdout lines
    (printed with `echo_other`: stdout must carry only replies); exits when the worker does."""
    while True:
        line = proc.stdout.readline()
        if not line:
            raise SystemExit("worker exited with %s" % proc.wait())
        line = line.decode()
        if line.startswith(tag + " "):
            return json.loads(line[len(tag) + 1:])
        if echo_other:
            print("NOT A REPLY (stdout must carry only replies):", line.rstrip())


def main():
    out = os.path.abspath(sys.argv[1])
    os.makedirs(out, exist_ok=True)
    tag = "@@clevrtex-0123456789abcdef@@"
    log = open(os.path.join(out, "blender.log"), "w")
    cmd = ["blender", "-b", "--factory-startup", "--python-exit-code", "1",
           "--python", os.path.join(SCRIPTS, "worker.py"), "--", "--tag", tag,
           "--threads", os.environ.get("THREADS", "0")]
    if os.environ.get("MATERIALS"):
        cmd += ["--materials", os.environ["MATERIALS"]]
    t0 = time.perf_counter()
    proc = subprocess.Popen(cmd, stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=log)

    def reply():
        return read_reply(proc, tag, echo_other=True)

    print("ready", reply(), "after %.2f s" % (time.perf_counter() - t0))
    n = 0
    for item in sys.argv[2:]:
        mode, scene = item.split(":", 1)
        modes = ["visibility", "final"] if mode == "both" else [mode]
        for m in modes:
            n += 1
            d = os.path.join(out, "%02d_%s_%s" % (n, os.path.basename(scene).split(".")[0], m))
            os.makedirs(d, exist_ok=True)
            req = {"type": "render", "id": n, "mode": "final" if m == "bad" else m,
                   "scene": os.path.abspath(scene) + (".missing" if m == "bad" else ""),
                   "out_dir": d}
            t = time.perf_counter()
            cpu = cpu_seconds(proc.pid)
            proc.stdin.write((json.dumps(req) + "\n").encode())
            proc.stdin.flush()
            r = reply()
            wall = time.perf_counter() - t
            if r.get("type") == "error":
                print("ERROR", r["message"])
                print(r["traceback"])
            else:
                print(json.dumps(r))
            print("  wall %.3f s, worker cpu %.2f s, load %s" % (
                wall, cpu_seconds(proc.pid) - cpu, os.getloadavg()[0]))
    proc.stdin.write(b'{"type": "quit"}\n')
    proc.stdin.flush()
    t = time.perf_counter()
    print("exit", proc.wait(), "in %.2f s" % (time.perf_counter() - t))


if __name__ == "__main__":
    main()
