"""`sasprobe bench --gpu-quick`: one short run for a machine with a GPU (minutes there; the
same code runs on llvmpipe at a reduced `--gpu-size`).

Frame times at 1920x1080 for 1CRN, 1TII (waters kept), 1AON whole and 6ZU5 with a
~300-atom navigation cube: unlit (every frame whole), the default lighting drawn whole
every frame, and the session frame (frame cache; the probe along the demo path, the camera
still), medians of FRAMES frames with the cases in turn; and the occlusion atlas's bake
for 1AON whole and for the 6ZU5 cube (programs compiled first, so the bake is timed warm);
and the session frame by structure (bench/render_sessions.py) at the same size, one round,
with the time to the first frame. The GL renderer and the GPU `nvidia-smi` names are
printed with the tables.
"""

from __future__ import annotations

import time

from sasprobe.cli.bench import render_sessions
from sasprobe.cli.bench.render_cases import (
    CUBE_TARGET_ATOMS,
    cube_for,
    demo_path,
    first_cube,
    follow_path,
    make_case,
    release,
    summary,
    time_cases,
)
from sasprobe.common.errors import UserError

TITLE = (
    "GPU check: frame times (unlit, default lighting, session), atlas bakes, sessions by structure"
)
STRUCTURES = ("1crn", "1tii", "1aon", "6zu5")
CUBE_ID = "6zu5"
FRAMES = 20
DEFAULT_SIZE = (1920, 1080)
SMOKE_SIZE = (64, 36)


def smoke_plan() -> dict:
    """run()'s options for `--smoke`: the two smallest reference structures (the second with
    the cube), three frames."""
    from sasprobe.cli.reference_data import MISSING, reference_structures

    ids = tuple(e.id for e in reference_structures()[:2])
    if not ids:
        raise UserError(MISSING)
    return {"frames": 3, "structures": ids, "cube_id": ids[-1]}


def run(
    size=DEFAULT_SIZE,
    frames: int = FRAMES,
    structures=STRUCTURES,
    cube_id: str = CUBE_ID,
    progress=None,
    first_frames: bool = True,
) -> dict:
    """The figures of the check; other `structures`, `cube_id` (the one drawn with a cube),
    `frames` and no `first_frames` (no daemons started) only shorten it for tests."""
    from sasprobe.cli.bench.lighting_precomputed import bake_seconds
    from sasprobe.cli.bench.machine import gl_renderer
    from sasprobe.cli.reference_data import reference_structures
    from sasprobe.molecule import DEFAULT_PROBE_RADIUS, load_structure
    from sasprobe.render.gl.context import create_headless_context
    from sasprobe.render.lighting.culling import Culling
    from sasprobe.render.lighting.settings import LightingSettings
    from sasprobe.render.lighting.uploaded_grid import UploadedGrid

    by_id = {e.id: e for e in reference_structures()}
    missing = [i for i in structures if i not in by_id]
    if missing:
        raise UserError(
            f"--gpu-quick needs the reference structures {', '.join(missing)} (tests/data/pdb/)"
        )
    gl = create_headless_context()
    out = {
        "gl_renderer": gl_renderer(),
        "size": list(size),
        "frames": frames,
        "rows": [],
        "bakes": [],
    }
    t_start = time.perf_counter()
    try:
        for sid in structures:
            structure = load_structure(by_id[sid].path, keep_water=sid == "1tii")
            cube, inside = (
                cube_for(structure, CUBE_TARGET_ATOMS) if sid == cube_id else (None, None)
            )
            path = demo_path(structure, frames, cube)
            lit = LightingSettings()
            cases = [
                make_case(gl, label, structure, size, lighting, cache, first_cube(path))
                for label, lighting, cache in (
                    ("unlit", None, False),
                    ("default lighting, whole", lit, False),
                    ("session frame", lit, True),
                )
            ]
            for case in cases:
                case.step = follow_path(case.renderer.scene, path)
            try:
                time_cases(gl, cases, frames)
                rows = summary(cases, "unlit", "default lighting, whole")
            finally:
                release(cases)
            out["rows"].append(
                {"id": sid, "atoms": structure.n_atoms, "cube_atoms": inside, "cases": rows}
            )
            if sid in ("1aon", cube_id):
                grid = UploadedGrid.from_structure(gl, structure, DEFAULT_PROBE_RADIUS)
                culling = Culling(nav_cube=(cube.center, cube.half)) if cube else Culling()
                out["bakes"].append(
                    {"id": sid + (" cube" if cube else " whole"), **bake_seconds(grid, culling)}
                )
                grid.release()
            if progress is not None:
                progress(sid)
        out["sessions"] = render_sessions.run_sessions(
            gl,
            by_id,
            sizes=(tuple(size),),
            structures=structures,
            frames=max(frames, 12),
            rounds=1,
            first_frames=first_frames,
            progress=(lambda what: progress(f"sessions: {what}"))
            if progress is not None
            else (lambda what: None),
        )
    finally:
        gl.release()
    out["wall_s"] = time.perf_counter() - t_start
    return out


def markdown(d: dict, gpu: str | None) -> str:
    w, h = d["size"]
    lines = [
        f"GL renderer: **{d['gl_renderer']}**; GPU: {gpu or 'none named by nvidia-smi'}; {w}x{h}, "
        "medians of "
        f"{d['frames']} frames, cases in turn; {d['wall_s']:.0f} s in all.",
        "",
        "| structure | atoms | unlit (ms) | default lighting, whole (ms) | session frame (ms) | "
        "session fps | "
        "session / unlit | whole / session |",
        "|---|---:|---:|---:|---:|---:|---:|---:|",
    ]
    for r in d["rows"]:
        c = r["cases"]
        name = r["id"] + (f" + {r['cube_atoms']}-atom cube" if r["cube_atoms"] else " whole")
        s = c["session frame"]
        lines.append(
            f"| {name} | {r['atoms']} | {c['unlit']['ms']:.2f} | "
            f"{c['default lighting, whole']['ms']:.2f} | "
            f"{s['ms']:.2f} | {1e3 / s['ms']:.0f} | {s['over_unlit']:.2f} | "
            f"{s['full_over_this']:.2f} |"
        )
    lines += [
        "",
        "| occlusion atlas bake | patches | accessibility alone (s) | light alone (s) | both, one "
        "bake (s) |",
        "|---|---:|---:|---:|---:|",
    ]
    for b in d["bakes"]:
        lines.append(
            f"| {b['id']} | {b['patches']} | {b['ambient_s']:.3f} | {b['sun_s']:.3f} | "
            f"{b['total_s']:.3f} |"
        )
    if "sessions" in d:
        lines += ["", render_sessions.markdown(d["sessions"])]
    return "\n".join(lines)
