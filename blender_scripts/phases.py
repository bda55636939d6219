"""Where a request's time goes: wall and CPU seconds per phase (docs/bridge-protocol.md,
`timings.phases`), the render calls split by the Cycles status line in effect.

Blender prints each render status line to file descriptor 1 (without its newline), flushes
it and then calls the `render_stats` handlers with no arguments. `capture(err_fd)` points fd 1
at a pipe: the handler drains it, notes the time against the status now in effect and
forwards every byte to `err_fd` (the worker's stderr); a thread forwards what is written
between renders. The handler and the thread share one lock, so the log keeps its order.
"""

import fcntl
import os
import select
import threading
import time

import bpy

# The phases, in the order a request goes through them (the Rust side's `BridgePhases`).
NAMES = ("build", "materials", "sync", "displacement", "bvh", "path_tracing", "denoise", "write",
         "other")

# Cycles status texts (3.4 to 5.0) -> phase; the first prefix found in the status wins.
_STATUS = (
    ("Computing Displacement", "displacement"),
    ("Tessellating", "displacement"),
    ("BVH", "bvh"),
    ("Denois", "denoise"),
    ("Sample", "path_tracing"),
    ("Path Tracing", "path_tracing"),
    ("Rendered", "path_tracing"),
    ("Synchroniz", "sync"),
    ("Updating", "sync"),
    ("Loading render kernels", "sync"),
    ("Initializing", "sync"),
)

_lock = threading.Lock()
_state = {"read": None, "err": None, "partial": b"", "events": None}


def phase_of(status):
    """The phase of a status line (`Fra:1 Mem:... | Scene, ViewLayer | Sample 1/64`)."""
    parts = [x.strip() for x in status.split("|")]
    k = next((i for i, x in enumerate(parts) if "ViewLayer" in x), None)
    msg = " | ".join(parts[k + 1:] if k is not None else parts[-1:])
    for prefix, name in _STATUS:
        if prefix in msg:
            return name
    return "other"


def _drain():
    """Forward what the pipe holds; return the status line in effect, or None. Hold _lock."""
    fd = _state["read"]
    status = None
    while True:
        try:
            chunk = os.read(fd, 65536)
        except BlockingIOError:
            break
        if not chunk:
            break
        view = memoryview(chunk)
        while view:
            view = view[os.write(_state["err"], view):]
        text = _state["partial"] + chunk
        lines = text.split(b"\n")
        _state["partial"] = lines[-1][-4096:]
        for line in lines[:-1]:
            if line.startswith(b"Fra:"):
                status = line
    if _state["partial"].startswith(b"Fra:"):
        status = _state["partial"]
    return None if status is None else status.decode("utf-8", "replace")


@bpy.app.handlers.persistent
def _on_stats(*_args):
    t, c = time.perf_counter(), time.process_time()
    with _lock:
        status = _drain()
        if _state["events"] is not None and status is not None:
            _state["events"].append((t, c, phase_of(status)))


def _forward():
    while True:
        select.select([_state["read"]], [], [])
        with _lock:
            _drain()


def capture(err_fd):
    """Point fd 1 at the pipe read back here (call once, after the replies' fd is taken)."""
    r, w = os.pipe()
    fcntl.fcntl(r, fcntl.F_SETFL, fcntl.fcntl(r, fcntl.F_GETFL) | os.O_NONBLOCK)
    os.dup2(w, 1)
    os.close(w)
    _state["read"], _state["err"] = r, err_fd
    bpy.app.handlers.render_stats.append(_on_stats)
    threading.Thread(target=_forward, name="clevrtex-status", daemon=True).start()


class Phases:
    """Wall and CPU seconds per phase of one request; add() timed steps, render() a render."""

    def __init__(self):
        self.t = {}

    def add(self, name, wall, cpu):
        w = self.t.setdefault(name, [0.0, 0.0])
        w[0] += wall
        w[1] += cpu

    def timed(self, name, fn):
        w0, c0 = time.perf_counter(), time.process_time()
        try:
            return fn()
        finally:
            self.add(name, time.perf_counter() - w0, time.process_time() - c0)

    def render(self, fn):
        """Run fn() (one bpy.ops.render.render) and split its time by the status in effect:
        the time before the first status line (depsgraph, session start) counts as sync."""
        w0, c0 = time.perf_counter(), time.process_time()
        with _lock:
            if _state["read"] is not None:
                _drain()
            _state["events"] = []
        try:
            result = fn()
        finally:
            w1, c1 = time.perf_counter(), time.process_time()
            with _lock:
                if _state["read"] is not None:
                    _drain()
                events, _state["events"] = _state["events"], None
            marks = [(w0, c0, "sync")] + events + [(w1, c1, None)]
            for (tw, tc, name), (tw2, tc2, _) in zip(marks, marks[1:]):
                self.add(name, tw2 - tw, tc2 - tc)
        return result

    def report(self):
        return {k: {"wall_s": round(v[0], 6), "cpu_s": round(v[1], 6)}
                for k, v in self.t.items()}
