"""`sasprobe bench render`: impostors against triangle meshes, the navigation cube on a
large structure against a small one drawn whole, and frame time against atom count (here);
the session frame by structure (bench/render_sessions.py; alone with --sessions); and the
frames of a session by scenario (bench/render_scenarios.py: the haptic session, an orbit,
the drifting cube; against PyMOL's `ray` where it is installed, bench/render_pymol.py).

Frame times are wall times of a whole frame with the GPU drained (glFinish) before
and after; per-pass times drain after every pass. Medians over repeats, ratios from
the same run. The GL renderer is named in the results: on llvmpipe (Mesa's software
rasteriser) the figures are CPU figures, not what a GPU does.
"""

from __future__ import annotations

import statistics
import time

import numpy as np

from sasprobe.cli.bench import BenchContext, BenchResult, render_scenarios, render_sessions
from sasprobe.cli.bench.charts import times_vs_atoms
from sasprobe.cli.bench.render_cases import CUBE_TARGET_ATOMS, cube_for
from sasprobe.cli.reference_data import MISSING, reference_structures
from sasprobe.common.errors import UserError
from sasprobe.common.progress import progress
from sasprobe.molecule import load_default, load_structure

TITLE = "Rendering: impostors vs meshes, navigation cube, frame time vs atoms, session scenarios"
MESH_TARGET_ATOMS = 60_000
QUICK_MESH_TARGET_ATOMS = 10_000  # --quick: a mesh frame of ~60k atoms takes seconds on llvmpipe


def add_arguments(parser) -> None:
    from sasprobe.cli.argtypes import size_type

    parser.add_argument(
        "--size",
        type=size_type,
        default=None,
        metavar="WxH",
        help="frame size (default 1280x720, --quick 640x360)",
    )
    parser.add_argument(
        "--scenario-size",
        type=size_type,
        default=None,
        metavar="WxH",
        help="frame size of the session scenarios (default 800x600, --quick 400x300)",
    )
    parser.add_argument(
        "--scenarios-only",
        action="store_true",
        help="only the session scenarios (haptic session, orbit, drifting cube; PyMOL where "
        "installed)",
    )
    parser.add_argument(
        "--sessions",
        action="store_true",
        help="only the session frame by structure: 1CRN, 1TII, 1AON, 6ZU5 at 1280x720 and 640x360, "
        "unlit and lit, with the time to the first frame (--quick: 1CRN and 1TII at 640x360)",
    )


def run(ctx: BenchContext, args=None) -> BenchResult:
    from sasprobe.render.gl.context import create_headless_context

    entries = reference_structures()
    if not entries:
        raise UserError(MISSING)
    if ctx.smoke:
        entries = entries[:2]
    size = getattr(args, "size", None) or (
        (64, 36) if ctx.smoke else (640, 360) if ctx.quick else (1280, 720)
    )
    scenario_size = getattr(args, "scenario_size", None) or (
        (64, 48) if ctx.smoke else (400, 300) if ctx.quick else (800, 600)
    )
    only_scenarios = getattr(args, "scenarios_only", False)
    repeats, mesh_repeats = (1, 1) if ctx.smoke else (3, 2) if ctx.quick else (9, 5)
    frames = 3 if ctx.smoke else 10 if ctx.quick else 30
    gl = create_headless_context()
    renderer_name = f"{gl.info['GL_RENDERER']} / OpenGL {gl.info['GL_VERSION']}"
    by_id = {e.id: e for e in entries}
    data = {
        "gl_renderer": renderer_name,
        "size": list(size),
        "repeats": repeats,
        "mesh_repeats": mesh_repeats,
    }
    charts = []
    if getattr(args, "sessions", False) or not only_scenarios:
        try:
            data["sessions"] = render_sessions.sessions_for_bench(gl, by_id, ctx)
        except BaseException:
            gl.release()
            raise
        path = ctx.chart_path("render_sessions.png")
        if path is not None:
            charts.append(render_sessions.chart(data["sessions"], path, renderer_name))
    if getattr(args, "sessions", False):
        gl.release()
        return BenchResult(
            "render",
            data,
            f"GL renderer: **{renderer_name}**.\n\n" + render_sessions.markdown(data["sessions"]),
            charts,
        )
    try:
        if not only_scenarios:
            structures = {
                e.id: load_structure(e.path)
                for e in progress(entries, "bench render: load", len(entries))
            }
            crambin = load_default()
            scaling = _scaling(gl, [(e.id, structures[e.id]) for e in entries], size, repeats)
            mesh_target = QUICK_MESH_TARGET_ATOMS if ctx.quick else MESH_TARGET_ATOMS
            mesh_id = min(structures, key=lambda k: abs(structures[k].n_atoms - mesh_target))
            sizes = [size] if ctx.quick else [size, (size[0] // 2, size[1] // 2)]
            data["modes"] = [
                _modes(gl, structures[mesh_id], s, mesh_repeats) | {"id": mesh_id} for s in sizes
            ]
            big_id = max(structures, key=lambda k: structures[k].n_atoms)
            data["cube"] = _cube(gl, structures[big_id], crambin, size, repeats) | {"id": big_id}
            data["scaling"] = scaling
            path = ctx.chart_path("render_frame_time.png")
            if path is not None:
                charts.append(_chart(path, scaling, renderer_name, size))
        data["scenarios"] = render_scenarios.run_scenarios(
            gl, by_id, scenario_size, frames, 1 if ctx.quick else 3
        )
    finally:
        gl.release()
    path = ctx.chart_path("render_frame_cache.png")
    if path is not None and data["scenarios"]["session"]:
        molecule_view = [r for r in data["scenarios"]["session"] if not r["demo_view"]]
        charts.append(render_scenarios.cache_figure(molecule_view[-1], path))
    for run in data["scenarios"]["session"]:
        del run["images"]  # pictures, not figures: the JSON stays small
    text = _markdown(data) if not only_scenarios else f"GL renderer: **{renderer_name}**."
    if "sessions" in data:
        text += "\n\n" + render_sessions.markdown(data["sessions"])
    return BenchResult(
        "render", data, text + "\n\n" + render_scenarios.markdown(data["scenarios"]), charts
    )


# ---------------------------------------------------------------- measurements
def _measure(cases, repeats: int) -> list[tuple[float, dict[str, float]]]:
    """Median frame time (s) and median per-pass times of each (renderer, camera, before)
    case. Frames of the cases are taken in turn, so load from other processes falls on
    all of them alike; frame and pass times come from the same frames (the GPU drained
    after each pass), after one warm-up frame per case."""
    for renderer, camera, _ in cases:
        renderer.render(camera)
        renderer.ctx.finish()
    frames: list[list[float]] = [[] for _ in cases]
    passes: list[list[dict]] = [[] for _ in cases]
    for _ in range(repeats):
        for i, (renderer, camera, before) in enumerate(cases):
            if before is not None:
                before()
            per_pass: dict[str, float] = {}
            renderer.ctx.finish()
            t0 = time.perf_counter()
            renderer.render(camera, pass_times=per_pass)
            renderer.ctx.finish()
            frames[i].append(time.perf_counter() - t0)
            passes[i].append(per_pass)
    return [
        (
            statistics.median(f),
            {n: statistics.median(p.get(n, 0.0) for p in ps) for n in set().union(*ps)},
        )
        for f, ps in zip(frames, passes)
    ]


def _atoms_pass_s(renderer, passes: dict[str, float]) -> float:
    """Median time of the renderer's atoms pass (quads, sprites or meshes, whatever its
    name); a frame that skipped it (a cache, a renamed pass) is an error, not a zero."""
    name = renderer.sphere_pass.name
    if passes.get(name, 0.0) <= 0.0:
        raise RuntimeError(
            f"the atoms pass {name!r} did not run in the timed frames (ran: "
            f"{', '.join(sorted(passes))})"
        )
    return passes[name]


def _renderer(gl, structure, size, mode="quad", nav_cube=None):
    from sasprobe.render.camera import Camera
    from sasprobe.render.renderer import Renderer
    from sasprobe.render.scene_state import SceneState

    scene = SceneState(structure, nav_cube=nav_cube)
    center, radius = scene.bounding_sphere()
    camera = Camera.fitted(center, radius, size[0] / size[1])
    # Whole frames: the frame cache would skip the atoms pass while the camera stands still.
    return Renderer(gl, scene, size, sphere_mode=mode, frame_cache=False), camera


def _scaling(gl, structures, size, repeats) -> list[dict]:
    cases, rows = [], []
    try:
        for name, structure in progress(structures, "bench render: set up", len(structures)):
            renderer, camera = _renderer(gl, structure, size)
            cases.append((renderer, camera, None))
            rows.append({"id": name, "n_atoms": structure.n_atoms})
        for row, (renderer, _, _), (frame, passes) in zip(rows, cases, _measure(cases, repeats)):
            row.update(frame_s=frame, spheres_s=_atoms_pass_s(renderer, passes), passes_s=passes)
    finally:
        for renderer, _, _ in cases:
            renderer.release()
    return rows


def _modes(gl, structure, size, repeats) -> dict:
    from sasprobe.render.passes.spheres import uv_sphere

    out = {
        "n_atoms": structure.n_atoms,
        "size": list(size),
        "mesh_triangles_per_atom": len(uv_sphere()[1]),
    }
    cases = []
    try:
        for mode in ("quad", "sprite", "mesh"):
            renderer, camera = _renderer(gl, structure, size, mode)
            cases.append((renderer, camera, None))
        for mode, (renderer, _, _), (frame, passes) in zip(
            ("quad", "sprite", "mesh"), cases, _measure(cases, repeats)
        ):
            out[mode] = {"frame_s": frame, "atoms_pass_s": _atoms_pass_s(renderer, passes)}
    finally:
        for renderer, _, _ in cases:
            renderer.release()
    out["mesh_over_quad_atoms_pass"] = out["mesh"]["atoms_pass_s"] / out["quad"]["atoms_pass_s"]
    out["mesh_over_quad_frame"] = out["mesh"]["frame_s"] / out["quad"]["frame_s"]
    return out


def _cube(gl, big, small, size, repeats) -> dict:
    still_cube, n_inside = cube_for(big, CUBE_TARGET_ATOMS)
    moving_cube, _ = cube_for(big, CUBE_TARGET_ATOMS)
    still, still_camera = _renderer(gl, big, size, nav_cube=still_cube)
    moving, moving_camera = _renderer(gl, big, size, nav_cube=moving_cube)
    whole, whole_camera = _renderer(gl, small, size)
    # The haptic arm drags the cube: new culling (a grid query) before every frame.
    step = np.array([0.013, -0.007, 0.011])

    def nudge():
        moving_cube.center = moving_cube.center + step

    try:
        (still_s, passes), (moving_s, _), (whole_s, _) = _measure(
            [
                (still, still_camera, None),
                (moving, moving_camera, nudge),
                (whole, whole_camera, None),
            ],
            repeats,
        )
        spheres = still.buffers.n_selected
    finally:
        for r in (still, moving, whole):
            r.release()
    return {
        "n_atoms": big.n_atoms,
        "cube_half_A": still_cube.half,
        "atoms_in_cube": n_inside,
        "spheres_drawn": spheres,
        "frame_s": still_s,
        "moving_frame_s": moving_s,
        "passes_s": passes,
        "small_id": small.name,
        "small_atoms": small.n_atoms,
        "small_whole_frame_s": whole_s,
        "ratio": still_s / whole_s,
        "moving_ratio": moving_s / whole_s,
    }


# ---------------------------------------------------------------- report
def _chart(path, scaling, renderer_name, size):
    series = [
        ([r["frame_s"] for r in scaling], "o-", "whole frame"),
        ([r["spheres_s"] for r in scaling], "s-", "sphere impostor pass"),
    ]
    title = f"Frame time vs atoms, {size[0]}x{size[1]}\n{renderer_name.split(' / ')[0]}"
    return times_vs_atoms(path, [r["n_atoms"] for r in scaling], series, title, fontsize=9)


def _markdown(d: dict) -> str:
    c = d["cube"]

    def ms(seconds):
        return f"{seconds * 1e3:.1f}"

    m0 = d["modes"][0]
    lines = [
        f"GL renderer: **{d['gl_renderer']}**, {d['size'][0]}x{d['size'][1]} unless noted; medians "
        "of "
        f"{d['repeats']} frames (impostors vs meshes: {d['mesh_repeats']}), the GPU drained "
        "(glFinish) after "
        "every pass; the frames of compared cases are taken in turn.",
        "",
        f"**Impostors vs meshes** ({m0['id']}, {m0['n_atoms']} atoms, mesh = "
        f"{m0['mesh_triangles_per_atom']} "
        "triangles per atom; atom pass / whole frame, ms):",
        "",
        "| size | ray-cast quads (default) | ray-cast point sprites | triangle meshes | meshes / "
        "quads, atom pass | meshes / quads, frame |",
        "|---|---:|---:|---:|---:|---:|",
    ]
    for m in d["modes"]:
        cells = " | ".join(
            f"{ms(m[k]['atoms_pass_s'])} / {ms(m[k]['frame_s'])}"
            for k in ("quad", "sprite", "mesh")
        )
        lines.append(
            f"| {m['size'][0]}x{m['size'][1]} | {cells} | "
            f"**{m['mesh_over_quad_atoms_pass']:.1f}x** | "
            f"{m['mesh_over_quad_frame']:.1f}x |"
        )
    lines += [
        "",
        f"**Navigation cube** ({c['id']}, {c['n_atoms']} atoms; cube half edge "
        f"{c['cube_half_A']:.2f} Å holding "
        f"{c['atoms_in_cube']} atoms; backbone trace elsewhere) against {c['small_id']} "
        f"({c['small_atoms']} atoms) drawn whole:",
        "",
        "| scene | frame (ms) | ratio to small whole |",
        "|---|---:|---:|",
        f"| {c['id']}, cube still | {ms(c['frame_s'])} | {c['ratio']:.2f} |",
        f"| {c['id']}, cube moving (culling every frame) | {ms(c['moving_frame_s'])} | "
        f"{c['moving_ratio']:.2f} |",
        f"| {c['small_id']} whole | {ms(c['small_whole_frame_s'])} | 1.00 |",
        "",
        "**Frame time vs atoms** (whole molecule, auto-fitted camera):",
        "",
        "| structure | atoms | sphere pass (ms) | whole frame (ms) | fps |",
        "|---|---:|---:|---:|---:|",
    ]
    for r in d["scaling"]:
        lines.append(
            f"| {r['id']} | {r['n_atoms']} | {ms(r['spheres_s'])} | {ms(r['frame_s'])} | "
            f"{1 / r['frame_s']:.1f} |"
        )
    return "\n".join(lines)
