"""PyMOL's `ray` beside the session frames (part of `sasprobe bench render`): the same
structure at the same size, with and without its shadows and antialiasing, timed in a child
process where `pymol-open-source` is importable (`pip install -e '.[peers]'`)."""

from __future__ import annotations

import json
import subprocess
import sys

PYMOL_SCRIPT = r"""
import json, statistics, sys, time
import pymol
from pymol import cmd
pymol.finish_launching(["pymol", "-qc"])
cmd.feedback("disable", "all", "everything")
path, w, h, repeats = sys.argv[1], int(sys.argv[2]), int(sys.argv[3]), int(sys.argv[4])
cmd.load(path, "m")
cmd.hide("everything")
cmd.show("spheres")
cmd.orient()
cmd.viewport(w, h)
out = {"version": cmd.get_version()[0], "atoms": cmd.count_atoms("all"),
       "max_threads": cmd.get("max_threads"), "antialias_default": int(cmd.get("antialias"))}
for shadows in (1, 0):
    for antialias in sorted({out["antialias_default"], 0}, reverse=True):
        cmd.set("ray_shadows", shadows)
        cmd.set("antialias", antialias)
        cmd.ray(w, h)
        times, cpu = [], []
        for _ in range(repeats):
            t0, c0 = time.perf_counter(), time.process_time()
            cmd.ray(w, h)
            times.append(time.perf_counter() - t0)
            cpu.append(time.process_time() - c0)
        out[f"shadows{shadows}_aa{antialias}_ms"] = statistics.median(times) * 1e3
        out[f"shadows{shadows}_aa{antialias}_cpu_ms"] = statistics.median(cpu) * 1e3
print("PYMOL_RESULT " + json.dumps(out))
"""


def pymol_available() -> bool:
    import importlib.util

    return importlib.util.find_spec("pymol") is not None


def pymol_ray(path, size, repeats: int) -> dict | None:
    """PyMOL's ray tracer on a structure file (spheres, oriented, w x h), with and without its
    shadows and antialiasing; None where pymol-open-source is not installed."""
    if not pymol_available():
        return None
    r = subprocess.run(
        [sys.executable, "-c", PYMOL_SCRIPT, str(path), str(size[0]), str(size[1]), str(repeats)],
        capture_output=True,
        text=True,
        timeout=900,
    )
    for line in r.stdout.splitlines():
        if line.startswith("PYMOL_RESULT "):
            return json.loads(line.split(" ", 1)[1])
    return {"error": (r.stderr.strip().splitlines() or ["no result"])[-1]}
