"""The frames a session draws, by scenario (part of `sasprobe bench render`):

(a) the haptic session: the camera still, the probe moving along the demo's path (the
    simulated arm's `scan` script through the haptic engine, as `sasprobe demo` runs it,
    one pose per 1/30 s), default lighting; the camera fitted to the molecule (as PyMOL's
    `orient` frames it), and once as the demo draws it: framing the navigation cube the
    poses carry, the cube's wire and trace drawn;
(b) an orbit: the camera turning 1° a frame about the molecule, the probe still;
(c) the cube drifting: a navigation cube holding about 300 atoms of the largest structure,
    moved a little every frame, the probe at its centre, the camera framing it.

Each is timed unlit (no lighting, every frame drawn whole), with the default lighting
drawn whole every frame (the full redraw) and with the frame planner (render/frame_planner.py);
the orbit and the drifting cube also with precomputed occlusion (AO and directional
shadows from the per-atom atlas; light fixed in the molecule frame; the bake before the
first frame is reported apart). Frames of the cases are taken in turn, so load from other
processes falls on all alike, and the load average is recorded beside the figures; each
frame's CPU time (this process, llvmpipe's threads included) is taken with its wall time,
and on a machine shared with other work the CPU-time ratios are the steadier ones. Where
`pymol-open-source` is importable, PyMOL's `ray` renders the session's structure at the
same size with and without its shadows in the same run (bench/render_pymol.py), between two
stretches of session frames, and is compared with their mean.
"""

from __future__ import annotations

import statistics
from functools import partial

import numpy as np

from sasprobe.cli.bench.render_cases import (
    CUBE_TARGET_ATOMS,
    Case,
    cube_for,
    demo_path,
    first_cube,
    follow_path,
    load_average,
    make_case,
    release,
    summary,
    time_cases,
)
from sasprobe.cli.bench.render_pymol import pymol_available, pymol_ray
from sasprobe.common.progress import progress
from sasprobe.molecule import load_structure


# ------------------------------------------------------------------ the scenarios
def run_scenarios(gl, by_id, size, frames: int, pymol_repeats: int) -> dict:
    """The three scenarios at `size`: (a) on 1CRN and 1TII (waters kept; PyMOL's ray between two
    stretches of 1TII's session frames), (b) on 1TII, (c) on the largest structure."""
    steps = progress(range(5), "bench render: scenarios", 5)
    out = {
        "size": list(size),
        "frames": frames,
        "load": [load_average()],
        "session": [],
        "orbit": [],
        "cube": [],
    }
    session_ids = [i for i in ("1crn", "1tii") if i in by_id]
    next(steps)
    for sid in session_ids:
        structure = load_structure(by_id[sid].path, keep_water=True)
        # 1TII: also PyMOL's ray, and the session as the demo frames it
        last = sid == session_ids[-1]
        peer = (
            partial(pymol_ray, by_id[sid].path, size, pymol_repeats)
            if last and pymol_available()
            else None
        )
        out["session"].append(
            {
                "id": sid,
                "atoms": structure.n_atoms,
                **session(gl, structure, size, frames, between=peer),
            }
        )
        if last:
            out["session"].append(
                {
                    "id": sid,
                    "atoms": structure.n_atoms,
                    **session(gl, structure, size, frames, demo_view=True),
                }
            )
    next(steps)
    orbit_id = session_ids[-1]
    structure = load_structure(by_id[orbit_id].path, keep_water=True)
    probe = demo_path(structure, 1)[0].proxy_A
    out["orbit"].append(
        {
            "id": orbit_id,
            "atoms": structure.n_atoms,
            **orbit(gl, structure, size, frames, probe),
        }
    )
    next(steps)
    big_id = max(by_id, key=lambda k: by_id[k].atoms)
    big = load_structure(by_id[big_id].path)
    out["cube"].append(
        {
            "id": big_id,
            "atoms": big.n_atoms,
            **drifting_cube(gl, big, size, frames),
        }
    )
    next(steps)
    next(steps)
    out["load"].append(load_average())
    return out


def session(gl, structure, size, frames: int, demo_view: bool = False, between=None) -> dict:
    """(a): the probe along the demo path, camera still; fitted to the molecule, or (with
    `demo_view`) to the poses' cube, which is drawn. `between()` (a peer's timing) runs
    after the frames, and session frames are timed again after it."""
    from sasprobe.render.lighting.settings import LightingSettings

    path = demo_path(structure, frames)
    cube = first_cube(path) if demo_view else None
    lit = LightingSettings()
    cases = [
        make_case(gl, "unlit", structure, size, None, False, cube),
        make_case(gl, "full redraw", structure, size, lit, False, cube),
        make_case(gl, "session (frame cache)", structure, size, lit, True, cube),
    ]

    for case in cases:
        case.step = follow_path(case.renderer.scene, path, with_cube=demo_view)
    try:
        time_cases(gl, cases, frames)
        # The same last frame
        full, kept = (
            cases[1].renderer.read_image(),
            cases[2].renderer.read_image(),
        )
        diff = np.abs(full.astype(int) - kept.astype(int)).max(axis=2)
        out = {
            "rows": summary(cases, "unlit", "full redraw"),
            "images": (full, kept),
            "demo_view": demo_view,
            "pixels_within_2": float((diff <= 2).mean()),
            "max_difference": int(diff.max()),
            "contact_fraction": float(np.mean([p.contact for p in path])),
            "probe_travel_A": float(
                np.sum(np.linalg.norm(np.diff([p.proxy_A for p in path], axis=0), axis=1))
            ),
        }
        if between is not None:
            out["peer"] = between()
            kept_case = cases[2]
            after = Case("after", kept_case.renderer, kept_case.camera, kept_case.step)
            time_cases(gl, [after], max(frames // 2, 3), warmup=0)
            out["session_after"] = {
                "ms": statistics.median(after.times) * 1e3,
                "cpu_ms": statistics.median(after.cpu) * 1e3,
            }
    finally:
        release(cases)
    return out


def orbit(gl, structure, size, frames: int, probe_center) -> dict:
    """(b): the camera turning 1° a frame, the probe still."""
    from sasprobe.render.lighting.settings import AOSettings, LightingSettings
    from sasprobe.render.scene_state import Probe

    lit = LightingSettings()
    baked = LightingSettings(shadows="precomputed", ao=AOSettings(mode="precomputed"))
    cases = [
        make_case(gl, "unlit", structure, size, None, False),
        make_case(gl, "full redraw", structure, size, lit, False),
        make_case(gl, "frame cache", structure, size, lit, True),
        make_case(gl, "precomputed AO + shadows", structure, size, baked, True),
    ]
    step_angle = np.radians(1.0)

    def step_of(case):
        axis = case.camera.up.copy()
        case.renderer.scene.probe = Probe(center=np.array(probe_center, dtype=np.float64))
        return lambda k: case.camera.orbit(axis, step_angle)

    for case in cases:
        case.step = step_of(case)
    try:
        bake_s = _first_frame_bake(gl, cases[-1])
        time_cases(gl, cases, frames)
        out = {"rows": summary(cases, "unlit", "full redraw"), "bake_s": bake_s}
    finally:
        release(cases)
    return out


def drifting_cube(gl, structure, size, frames: int) -> dict:
    """(c): a ~300-atom cube of the largest structure moving every frame, the probe inside."""
    from sasprobe.render.camera import Camera
    from sasprobe.render.lighting.settings import AOSettings, LightingSettings
    from sasprobe.render.scene_state import NavCube, Probe

    cube, inside = cube_for(structure, CUBE_TARGET_ATOMS)
    camera = Camera.fitted(cube.center, cube.half * np.sqrt(3.0), size[0] / size[1])
    lit = LightingSettings()
    baked = LightingSettings(shadows="precomputed", ao=AOSettings(mode="precomputed"))
    cases = [
        make_case(
            gl,
            label,
            structure,
            size,
            lighting,
            cache,
            NavCube(cube.center.copy(), cube.half),
            camera,
        )
        for label, lighting, cache in (
            ("unlit", None, False),
            ("full redraw", lit, False),
            ("frame cache", lit, True),
            ("precomputed AO + shadows", baked, True),
        )
    ]
    drift = np.array([0.05, -0.03, 0.04])  # Å per frame: 1.5-2 Å/s at 30 fps

    def step_of(scene):
        def step(k: int) -> None:
            scene.nav_cube = NavCube(cube.center + k * drift, cube.half)
            scene.probe = Probe(center=scene.nav_cube.center + [0.0, 0.0, 0.5 * cube.half])

        return step

    for case in cases:
        case.step = step_of(case.renderer.scene)
    try:
        time_cases(gl, cases, frames)
        out = {
            "rows": summary(cases, "unlit", "full redraw"),
            "cube_half_A": cube.half,
            "atoms_in_cube": inside,
        }
    finally:
        release(cases)
    return out


def _first_frame_bake(gl, case: Case) -> float:
    """Draw the case's first frame with its atlas baking; the bake's own time (s)."""
    case.renderer.render(case.camera)
    gl.finish()
    atlas = case.renderer.lighting.ao.program("atlas")
    return atlas.bake_seconds


# ------------------------------------------------------------------ report
def cache_figure(run: dict, path):
    """The session's last frame drawn whole and from the kept molecule layer, and their
    difference."""
    import matplotlib.pyplot as plt

    full, kept = run["images"]
    diff = np.abs(full.astype(int) - kept.astype(int)).max(axis=2)
    fig, axes = plt.subplots(1, 3, figsize=(12, 3.6), dpi=110)
    for ax, image, title in (
        (axes[0], full, "full redraw"),
        (axes[1], kept, "frame cache (probe moved)"),
    ):
        ax.imshow(image)
        ax.set_title(title, fontsize=8)
    im = axes[2].imshow(diff, cmap="magma", vmin=0, vmax=8)
    axes[2].set_title(
        f"|difference|: max {diff.max()}/255,\n{100 * (diff <= 2).mean():.3f} % of pixels within "
        "2/255",
        fontsize=8,
    )
    fig.colorbar(im, ax=axes[2], shrink=0.8, label="/255")
    for ax in axes:
        ax.set_xticks([])
        ax.set_yticks([])
    fig.suptitle(f"{run['id']}: a session frame, default lighting", fontsize=9)
    fig.savefig(path, bbox_inches="tight")
    plt.close(fig)
    return path


def markdown(d: dict) -> str:
    size = f"{d['size'][0]}x{d['size'][1]}"
    lines = [
        f"**Scenarios** ({size}, medians of {d['frames']} frames per case, cases in turn; load "
        "average "
        f"{d['load'][0]} at the start, {d['load'][1]} at the end):",
        "",
        "| scenario | structure | case | ms / frame | CPU ms / frame | × unlit | full redraw / "
        "this | "
        "× unlit (CPU) | full / this (CPU) | layer kept |",
        "|---|---|---|---:|---:|---:|---:|---:|---:|---:|",
    ]
    for key, title in (
        ("session", "(a) haptic session"),
        ("orbit", "(b) orbit"),
        ("cube", "(c) cube drifting"),
    ):
        for run in d[key]:
            name = run["id"] + (" (the demo's view)" if run.get("demo_view") else "")
            for label, r in run["rows"].items():
                kept = (
                    ""
                    if r["cache_hits"] is None
                    else f"{r['cache_hits']}/{r['cache_hits'] + r['cache_misses']}"
                )
                lines.append(
                    f"| {title} | {name} | {label} | {r['ms']:.1f} | {r['cpu_ms']:.1f} | "
                    f"{r['over_unlit']:.2f} | {r['full_over_this']:.2f} | "
                    f"{r['over_unlit_cpu']:.2f} | "
                    f"{r['full_over_this_cpu']:.2f} | {kept} |"
                )
    for run in d["session"]:
        lines.append(
            f"\nSession, {run['id']}{' (the demo view)' if run['demo_view'] else ''}: the probe "
            f"travelled {run['probe_travel_A']:.1f} Å, in contact "
            f"{100 * run['contact_fraction']:.0f} % of the frames; the last frame from the kept "
            "layer and "
            f"drawn whole agree within 2/255 on {100 * run['pixels_within_2']:.3f} % of the pixels "
            f"(largest difference {run['max_difference']}/255)."
        )
    for run in d["orbit"]:
        lines.append(
            f"Orbit, {run['id']}: the atlas baked in {run['bake_s']:.2f} s before the first frame."
        )
    for run in d["cube"]:
        lines.append(
            f"Drifting cube, {run['id']}: half edge {run['cube_half_A']:.2f} Å, "
            f"{run['atoms_in_cube']} atoms; "
            "the atlas is baked again every frame (the culling changes)."
        )
    around = next((r for r in d["session"] if "peer" in r), None)
    p = None if around is None else around["peer"]
    if p is None:
        lines.append("\nPyMOL: pymol-open-source is not installed (`pip install -e '.[peers]'`).")
    elif "error" in p:
        lines.append(f"\nPyMOL could not run: {p['error']}")
    else:
        before, after = around["rows"]["session (frame cache)"], around["session_after"]
        session = {key: (before[key] + after[key]) / 2 for key in ("ms", "cpu_ms")}
        lines += [
            "",
            f"**PyMOL {p['version']}** `ray` on {around['id']} ({p['atoms']} atoms, spheres, "
            f"{size}, "
            f"max_threads {p['max_threads']}), same run, between two stretches of session frames "
            f"({before['ms']:.1f} and {after['ms']:.1f} ms); ratio = PyMOL / their mean:",
            "",
            "| PyMOL setting | ms | CPU ms | PyMOL / session frame | (CPU) |",
            "|---|---:|---:|---:|---:|",
        ]
        aa = p["antialias_default"]
        for shadows in (1, 0):
            for antialias in sorted({aa, 0}, reverse=True):
                ms, cpu = (
                    p[f"shadows{shadows}_aa{antialias}_ms"],
                    p[f"shadows{shadows}_aa{antialias}_cpu_ms"],
                )
                lines.append(
                    f"| ray_shadows {shadows}, antialias {antialias} | {ms:.0f} | {cpu:.0f} | "
                    f"{ms / session['ms']:.1f}× | {cpu / session['cpu_ms']:.1f}× |"
                )
    return "\n".join(lines)
