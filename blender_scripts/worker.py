"""The Blender worker: renders scene files (and single materials, for the contact sheet and
the material checks) on request, over the protocol of docs/bridge-protocol.md.

Run as `blender -b --factory-startup --python-exit-code 1 --python worker.py -- --tag TAG
[--threads T] [--materials materials.json]`, or, with PyPI's `bpy` module, as `python
worker.py -- --tag TAG ... --factory-startup` (the module has no command line of its own, so
`--factory-startup` asks the bridge to reset to factory settings itself).

Stdout discipline: before anything else the worker keeps a private duplicate of stdout for
its replies and points file descriptor 1 (C stdio, Python's print, add-ons, Cycles' progress)
at stderr. So stdout carries nothing but replies, each a single `TAG <json>\n` written with
one write(2); the tag is still checked by the reader, as a second line of defence.
"""

import argparse
import ctypes
import json
import os
import select
import sys
import time
import threading
import traceback

BRIDGE_VERSION = 1

# Sibling modules live beside this script (the Rust side writes them all to one temp dir).
HERE = os.path.dirname(os.path.abspath(__file__))
if HERE not in sys.path:
    sys.path.insert(0, HERE)


def _take_stdout():
    """Return a private fd for replies; send everything else written to fd 1 to stderr."""
    sys.stdout.flush()
    try:
        ctypes.CDLL(None).fflush(None)  # Blender's buffered C stdout, before we move it
    except Exception:
        pass
    reply_fd = os.dup(1)
    os.dup2(2, 1)
    return reply_fd


class Replier:
    def __init__(self, fd, tag):
        self.fd = fd
        self.tag = tag

    def send(self, message):
        line = ("%s %s\n" % (self.tag, json.dumps(message, separators=(",", ":")))).encode()
        view = memoryview(line)
        while view:
            n = os.write(self.fd, view)
            view = view[n:]


def _parse_args(argv):
    argv = argv[argv.index("--") + 1:] if "--" in argv else []
    p = argparse.ArgumentParser(prog="worker.py")
    p.add_argument("--tag", required=True)
    p.add_argument("--threads", type=int, default=0)
    p.add_argument("--materials", default=None)
    p.add_argument("--device", default="CPU",
                   help="CPU, or KIND:INDEX, e.g. CUDA:1: the index-th GPU of that kind")
    p.add_argument("--factory-startup", action="store_true",
                   help="reset to factory settings first (bpy as a Python module)")
    return p.parse_args(argv)


def _load_catalogue(path):
    if path is None:
        return None  # development: every material name accepted, empty recipe
    with open(path, "r", encoding="utf-8") as f:
        doc = json.load(f)
    return doc["materials"]


class Worker:
    def __init__(self, args, replier):
        import compat

        if args.factory_startup:
            compat.factory_startup()
        kind, _, index = args.device.partition(":")
        compat.DEVICE = (kind.upper(), int(index or 0))
        import builder
        import materials
        import phases

        phases.capture(2)
        self.phases = phases

        self.builder = builder
        self.compat = compat
        self.materials = materials
        self.args = args
        self.replier = replier
        self.catalogue = _load_catalogue(args.materials)
        # Keep Cycles' session between requests on a GPU (a new one means a new device
        # context and kernel load); on the CPU a new one costs ~1-4 ms, while a kept one
        # leaves a TBB thread of bpy 4.5/5.0 spinning through the build and material work
        # between renders (measured: CPU seconds of `build` twice its wall time).
        self.keep_session = compat.DEVICE[0] != "CPU"
        self.built = None

    def ready(self):
        self.replier.send({
            "type": "ready",
            "bridge_version": BRIDGE_VERSION,
            "blender_version": self.compat.version_string(),
            "cycles_devices": self.compat.cycles_devices(),
            "gpus": self.compat.cycles_gpus(),
            "cuda_kernels": self.compat.cuda_kernels(),
            "features": self.compat.features(),
            "compat": self.compat.parity_settings(),
        })

    def _scene_key(self, path):
        st = os.stat(path)
        return (os.path.abspath(path), st.st_mtime_ns, st.st_size)

    def render(self, req):
        b = self.builder
        mode = req.get("mode")
        if mode not in ("visibility", "final"):
            raise ValueError("unknown render mode `%s` (expected `visibility` or `final`)" % mode)
        path = req["scene"]
        out_dir = req["out_dir"]
        if not os.path.isdir(out_dir):
            raise FileNotFoundError("output directory `%s` does not exist" % out_dir)
        key = self._scene_key(path)
        build_s = 0.0
        ph = self.phases.Phases()
        if self.built is None or self.built.key != key:
            self.built = None  # a failed build must not be reused
            spec = b.load_scene_file(path)
            built = ph.timed("build", lambda: b.build(spec, key, self.args.threads))
            build_s += built.build_s
            self.built = built
        # The object-index pass does not depend on materials: the visibility check skips
        # them (2-3x cheaper per check, measured), `final` builds them with displacement.
        if mode == "final":
            build_s += ph.timed("materials", lambda: b.assign_materials(
                self.built, self.catalogue, self.materials.build_material, displacement=True))
        if mode == "visibility":
            files, timings = b.render_visibility(self.built, out_dir, ph)
        else:
            files, timings = b.render_final(self.built, out_dir, req.get("shadow_samples"), ph)
        timings["build_s"] = build_s
        timings["phases"] = ph.report()
        return {
            "type": "done",
            "id": req.get("id"),
            "mode": mode,
            "files": files,
            "timings": timings,
            "projected": b.projected(self.built),
            "data_blocks": b.data_block_counts(),
        }

    def material(self, req):
        """One material on its own small scene (contact sheet, checks, statistics)."""
        import material_tool

        name = req["name"]
        if self.catalogue is None:
            recipe = {}
        elif name in self.catalogue:
            recipe = self.catalogue[name]
        else:
            raise KeyError("material `%s` is not in materials.json" % name)
        # The material scenes start from factory settings: whatever scene was built is gone.
        self.built = None
        result = material_tool.render(req, recipe, self.args.threads)
        result.update({"type": "done", "id": req.get("id"), "mode": req.get("mode"),
                       "name": name})
        return result

    def inspect(self, req):
        """A user `.blend` material's node group, inputs, outputs and textures
        (materials.inspect_blend), checked by the Rust side before a run."""
        result = self.materials.inspect_blend(req["path"], req.get("group"),
                                              req.get("packed_dir"))
        result.update({"type": "done", "id": req.get("id")})
        return result

    def handle(self, req):
        kind = req.get("type")
        if kind == "render":
            return self.render(req)
        if kind == "inspect":
            return self.inspect(req)
        if kind == "material":
            return self.material(req)
        if kind == "ping":
            return {"type": "pong", "id": req.get("id")}
        raise ValueError("unknown request type `%s`" % kind)

    def loop(self, stdin):
        held = False  # whether Cycles' session is kept from the last request
        while True:
            raw = stdin.next(IDLE_RELEASE_S if held else None, self.builder.release_render)
            held = False
            if not raw:
                return  # EOF: the parent is gone or done
            raw = raw.strip()
            if not raw:
                continue
            req_id = None
            try:
                req = json.loads(raw.decode("utf-8"))
                if not isinstance(req, dict):
                    raise ValueError("request is not a JSON object")
                req_id = req.get("id")
                if req.get("type") == "quit":
                    return
                reply = self.handle(req)
                held = self.keep_session and req.get("type") == "render"
                if not held:
                    self.builder.release_render()
            except Exception as exc:
                self.built = None  # state after a failure is unknown: rebuild next time
                self.builder.release_render()
                reply = {
                    "type": "error",
                    "id": req_id,
                    "message": "%s: %s" % (type(exc).__name__, exc),
                    "traceback": traceback.format_exc(),
                }
            self.replier.send(reply)


# Seconds without a request after which a GPU worker frees Cycles' session
# (builder.release_render; a CPU worker frees it after every request: Worker.keep_session).
# Kept while requests keep coming, the session (device, kernels, synced scene) serves the
# next request; freed when idle, no TBB thread of bpy 4.5/5.0 spins (docs/notes/performance.md,
# "Idle thread"). A busy worker's gap between requests is the Rust side's post-processing,
# tens of milliseconds at 320x240.
IDLE_RELEASE_S = 0.25


class Lines:
    """Request lines from file descriptor `fd`; next(idle_s, on_idle) calls on_idle() once
    when no line comes within idle_s seconds, then keeps waiting."""

    def __init__(self, fd):
        self.fd = fd
        self.buf = b""

    def next(self, idle_s=None, on_idle=None):
        while b"\n" not in self.buf:
            if idle_s is not None:
                ready, _, _ = select.select([self.fd], [], [], idle_s)
                if not ready:
                    on_idle()
                    idle_s = None
                    continue
            chunk = os.read(self.fd, 65536)
            if not chunk:
                rest, self.buf = self.buf, b""
                return rest  # EOF: the rest, then b""
            self.buf += chunk
        line, self.buf = self.buf.split(b"\n", 1)
        return line + b"\n"


def _proc_stat(pid):
    """(parent pid, start time) of process `pid` from /proc, or None if it is gone."""
    try:
        with open("/proc/%d/stat" % pid) as f:
            fields = f.read().rsplit(")", 1)[1].split()
        return int(fields[1]), int(fields[19])
    except (OSError, ValueError, IndexError):
        return None


def _ancestor_start(pid):
    """The start time of `pid` if it is our parent or an ancestor (a wrapper script may sit
    between clevrtex and Blender), else None."""
    p = os.getppid()
    for _ in range(32):
        if p <= 1:
            return None
        stat = _proc_stat(p)
        if stat is None:
            return None
        if p == pid:
            return stat[1]
        p = stat[0]
    return None


def _die_with_parent():
    """Never outlive the clevrtex process that started us, even when it is killed with SIGKILL
    (no chance for it to stop us): on Linux, ask the kernel for SIGKILL when our parent dies,
    then check that the process named by CLEVRTEX_PARENT_PID is still our parent, or an
    ancestor when a wrapper script started us (it may have died before the request). Behind
    a wrapper, the kernel's signal follows the wrapper, not clevrtex, so a watchdog thread
    also exits when clevrtex is gone (and a closed stdin ends the request loop). Elsewhere, or
    without the variable, nothing happens."""
    parent = os.environ.get("CLEVRTEX_PARENT_PID")
    if not parent or not sys.platform.startswith("linux"):
        return
    try:
        PR_SET_PDEATHSIG = 1
        ctypes.CDLL(None, use_errno=True).prctl(PR_SET_PDEATHSIG, 9, 0, 0, 0)
    except Exception:
        return
    parent = int(parent)
    if os.getppid() == parent:
        return
    start = _ancestor_start(parent)
    if start is None:
        os._exit(1)

    def watch():
        while True:
            time.sleep(1.0)
            stat = _proc_stat(parent)
            if stat is None or stat[1] != start:
                os._exit(1)

    threading.Thread(target=watch, name="clevrtex-parent-watch", daemon=True).start()


def _import_bpy_on(threads):
    """Import `bpy` (PyPI's module) while this process may run on `threads` CPUs only, then
    allow every CPU again: Blender sizes its TBB scheduler (scene sync, BVH builds, material
    and mesh work) once, at import, from the CPUs the process may use, and `--threads` reaches
    only Cycles' own threads. So a `--threads 1` worker of bpy 4.5 kept a second TBB thread
    busy (spinning in sched_yield while it waits for work): 2.85 host CPU-s per `full` 320x240
    image against Blender 3.4's 1.45 (docs/notes/performance.md, "bpy 4.5 with `--threads
    1`"). The CPUs are allowed again at once, so workers are not pinned. Nothing happens in
    Blender's executable (bpy is imported before this script runs, sized by its own `-t`),
    with 0 threads (Blender's choice), with as many threads as CPUs, or where the affinity
    mask cannot be read or set."""
    if "bpy" in sys.modules or threads <= 0 or not hasattr(os, "sched_setaffinity"):
        return
    try:
        allowed = os.sched_getaffinity(0)
        if threads >= len(allowed):
            return
        os.sched_setaffinity(0, set(sorted(allowed)[:threads]))
    except OSError:
        return
    try:
        import bpy  # noqa: F401 (imported for its side effect: TBB sized now)
    finally:
        os.sched_setaffinity(0, allowed)


def main():
    _die_with_parent()
    args = _parse_args(sys.argv)
    replier = Replier(_take_stdout(), args.tag)
    t0 = time.perf_counter()
    try:
        _import_bpy_on(args.threads)
        worker = Worker(args, replier)
    except Exception as exc:
        replier.send({"type": "error", "id": None, "message": "worker start failed: %s" % exc,
                      "traceback": traceback.format_exc()})
        raise
    worker.ready()
    print("clevrtex worker ready in %.2f s" % (time.perf_counter() - t0), file=sys.stderr)
    worker.loop(Lines(0))
    sys.stderr.flush()


main()
