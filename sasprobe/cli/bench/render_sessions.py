"""The session frame by structure (`sasprobe bench render --sessions`; part of every full
`sasprobe bench render`, and of `--gpu-quick`).

What a renderer following a daemon draws in the workspace view, on 1CRN, 1TII, 1AON and
6ZU5: the simulated arm's `scan` script through the haptic engine (the demo's session, one
pose per 1/30 s: render_cases.demo_path) puts the probe, its touched atom and the
daemon's default navigation cube into the scene, the camera frames the cube, and the
renderer is `render --connect`'s (frame planner, probe plane, lights turning with the
camera) — unlit (no lighting passes) and with the default lighting. Per structure, size
and lighting: the median frame (wall and this process's CPU time, llvmpipe's threads
included), the frames that kept the molecule layer, the first frame in this process (the
renderer made, the structure's first frame drawn), and `sasprobe render --connect
--headless --frames 1` against a running daemon (`sasprobe daemon --device sim:scan`),
wall time from process start to exit. The frames of every case of a size are taken in
turn, so load from other processes falls on all alike; the whole is repeated, and each
frame time's ratio to 1CRN's is given as the median of the rounds with its range (CPU
time is the steadier on a shared machine).
"""

from __future__ import annotations

import os
import resource
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from sasprobe.cli.bench import BenchContext
from sasprobe.cli.bench.render_cases import Case, demo_path, time_cases
from sasprobe.common.errors import UserError
from sasprobe.common.progress import progress_bar

STRUCTURES = ("1crn", "1tii", "1aon", "6zu5")
SIZES = ((1280, 720), (640, 360))
QUICK_STRUCTURES = ("1crn", "1tii")
QUICK_SIZES = ((640, 360),)
FRAMES, QUICK_FRAMES = 40, 12
ROUNDS, QUICK_ROUNDS = 3, 1
FIRST_FRAME_RUNS = 2  # `render --connect --frames 1` per structure and size; the median is given
LIGHTINGS = ("unlit", "lit")
DAEMON_READY_S = 180.0


def _case(gl, structure, path, size, lit: bool):
    from sasprobe.render.app import RenderOptions, build_scene, make_renderer
    from sasprobe.render.lighting.presets import PRESETS
    from sasprobe.render.scene_state import NavCube, Probe
    from sasprobe.render.workspace_view import workspace_camera

    opts = RenderOptions(
        size=size, connect="", lighting=PRESETS["default"].lighting if lit else None
    )
    scene = build_scene(structure, opts)
    aspect = size[0] / size[1]

    def put(k: int) -> None:
        pose = path[k % len(path)]
        scene.probe = Probe(
            center=np.array(pose.proxy_A, dtype=np.float64),
            touched_atom=pose.touched_atoms[0] if pose.touched_atoms else -1,
        )
        cube = NavCube(np.array(pose.cube_center_A, dtype=np.float64), float(pose.cube_half_A))
        if scene.nav_cube is None or scene.nav_cube.key() != cube.key():
            scene.nav_cube = cube
        follow = workspace_camera(scene.nav_cube, aspect)
        case.camera.eye, case.camera.target, case.camera.up = follow.eye, follow.target, follow.up

    put_first = path[0]
    scene.nav_cube = NavCube(
        np.array(put_first.cube_center_A, dtype=np.float64), float(put_first.cube_half_A)
    )
    t0 = time.perf_counter()
    renderer = make_renderer(gl, scene, size, opts)
    case = Case("lit" if lit else "unlit", renderer, workspace_camera(scene.nav_cube, aspect), put)
    put(0)
    renderer.render(case.camera)
    gl.finish()
    case.first_frame_s = time.perf_counter() - t0
    return case


def _first_frames(by_id, ids, sizes, runs: int, progress) -> dict:
    """`render --connect --headless --frames 1` against a running sim:scan daemon, by
    (structure, size): (wall seconds, CPU seconds of the process), the medians of `runs`."""
    from sasprobe.cli.children import DaemonChild

    out = {}
    for sid in ids:
        folder = Path(tempfile.mkdtemp(prefix="sps"))
        pub, ctl = f"ipc://{folder}/p", f"ipc://{folder}/c"
        child = DaemonChild(
            [
                "--device",
                "sim:scan",
                "--molecule",
                str(by_id[sid].path),
                "--pub",
                pub,
                "--ctl",
                ctl,
            ],
            folder / "daemon.log",
        )
        try:
            child.wait_ready(DAEMON_READY_S)
            for size in sizes:
                walls, cpus = [], []
                for _ in range(runs):
                    before, t0 = resource.getrusage(resource.RUSAGE_CHILDREN), time.perf_counter()
                    r = subprocess.run(
                        [
                            sys.executable,
                            "-m",
                            "sasprobe",
                            "render",
                            "--connect",
                            pub,
                            "--control",
                            ctl,
                            "--headless",
                            "--frames",
                            "1",
                            "--size",
                            f"{size[0]}x{size[1]}",
                        ],
                        capture_output=True,
                        text=True,
                        timeout=300,
                        cwd=folder,  # its picture (sasprobe-render.png) lands there
                    )
                    wall, after = (
                        time.perf_counter() - t0,
                        resource.getrusage(resource.RUSAGE_CHILDREN),
                    )
                    cpu = after.ru_utime - before.ru_utime + after.ru_stime - before.ru_stime
                    walls.append(wall if r.returncode == 0 else float("nan"))
                    cpus.append(cpu if r.returncode == 0 else float("nan"))
                out[(sid, tuple(size))] = (statistics.median(walls), statistics.median(cpus))
        finally:
            child.stop(30.0)
            shutil.rmtree(folder, ignore_errors=True)
        progress(f"first frame {sid}")
    return out


def run_sessions(
    gl,
    by_id,
    quick: bool = False,
    sizes=None,
    structures=None,
    frames: int | None = None,
    rounds: int | None = None,
    first_frames=True,
    progress=lambda what: None,
) -> dict:
    """The figures of the sessions table (see the module's docstring); `first_frames`: True,
    False, or the structures whose `render --connect --frames 1` is timed."""
    from sasprobe.molecule import load_structure

    load = [os.getloadavg()[0]]
    structures = structures or (QUICK_STRUCTURES if quick else STRUCTURES)
    sizes = [tuple(s) for s in (sizes or (QUICK_SIZES if quick else SIZES))]
    frames = frames or (QUICK_FRAMES if quick else FRAMES)
    rounds = rounds or (QUICK_ROUNDS if quick else ROUNDS)
    loaded = {sid: load_structure(by_id[sid].path) for sid in structures}
    paths = {sid: demo_path(s, frames) for sid, s in loaded.items()}
    progress("scan paths")
    rows = []
    for size in sizes:
        cases = {}
        try:
            for sid in structures:
                for lighting in LIGHTINGS:
                    cases[sid, lighting] = _case(
                        gl, loaded[sid], paths[sid], size, lighting == "lit"
                    )
            per_round = {key: [] for key in cases}
            for _ in range(rounds):
                for case in cases.values():
                    case.times, case.cpu = [], []
                    case.layer_before = case.renderer.planner.layer_counts()
                time_cases(gl, list(cases.values()), frames, warmup=0)
                for key, case in cases.items():
                    counts = case.renderer.planner.layer_counts()
                    per_round[key].append(
                        {
                            "ms": statistics.median(case.times) * 1e3,
                            "cpu_ms": statistics.median(case.cpu) * 1e3,
                            "kept": counts["kept"] - case.layer_before["kept"],
                        }
                    )
                progress(f"{size[0]}x{size[1]} round")
            for (sid, lighting), case in cases.items():
                runs = per_round[sid, lighting]
                base = per_round[structures[0], lighting]
                ratios = {
                    key: [r[key] / b[key] for r, b in zip(runs, base)] for key in ("ms", "cpu_ms")
                }
                rows.append(
                    {
                        "id": sid,
                        "atoms": loaded[sid].n_atoms,
                        "size": list(size),
                        "lighting": lighting,
                        "cube_half_A": paths[sid][0].cube_half_A,
                        "spheres": int(case.renderer.buffers.n_selected),
                        "ms": statistics.median(r["ms"] for r in runs),
                        "cpu_ms": statistics.median(r["cpu_ms"] for r in runs),
                        "kept": int(statistics.median(r["kept"] for r in runs)),
                        "frames": frames,
                        "first_frame_s": case.first_frame_s,
                        **{
                            f"over_{structures[0]}"
                            + ("_cpu" if key == "cpu_ms" else ""): statistics.median(v)
                            for key, v in ratios.items()
                        },
                        **{
                            f"over_{structures[0]}_cpu_range": [
                                min(ratios["cpu_ms"]),
                                max(ratios["cpu_ms"]),
                            ],
                            f"over_{structures[0]}_range": [min(ratios["ms"]), max(ratios["ms"])],
                        },
                    }
                )
        finally:
            for case in cases.values():
                case.renderer.release()
    out = {
        "structures": list(structures),
        "sizes": [list(s) for s in sizes],
        "frames": frames,
        "rounds": rounds,
        "rows": rows,
        "load": load,
    }
    for row in rows:  # lit against unlit, same structure and size, same rounds
        unlit = next(
            r
            for r in rows
            if r["id"] == row["id"] and r["size"] == row["size"] and r["lighting"] == "unlit"
        )
        row["lit_over_unlit"] = row["ms"] / unlit["ms"]
        row["lit_over_unlit_cpu"] = row["cpu_ms"] / unlit["cpu_ms"]
    joined = structures if first_frames is True else tuple(first_frames or ())
    if joined:
        firsts = _first_frames(by_id, joined, sizes, 1 if quick else FIRST_FRAME_RUNS, progress)
        for row in rows:
            if row["id"] in joined:
                row["connect_frames_1_s"], row["connect_frames_1_cpu_s"] = firsts[
                    row["id"], tuple(row["size"])
                ]
    load.append(os.getloadavg()[0])
    return out


def sessions_for_bench(gl, by_id, ctx: BenchContext) -> dict:
    """The sessions table as `sasprobe bench render` runs it, with a progress bar; --smoke:
    the structures it has, tiny, one of them joined by `render --connect`."""
    if ctx.smoke:
        wanted, plan = tuple(by_id), {"sizes": ((64, 36),), "frames": 3, "rounds": 1}
        plan["first_frames"] = wanted[:1]
    else:
        wanted, plan = (QUICK_STRUCTURES if ctx.quick else STRUCTURES), {}
    missing = [sid for sid in wanted if sid not in by_id]
    if missing:
        raise UserError(
            f"bench render: the session table needs the reference structures {', '.join(missing)}"
        )
    sizes = plan.get("sizes") or (QUICK_SIZES if ctx.quick else SIZES)
    rounds = plan.get("rounds") or (QUICK_ROUNDS if ctx.quick else ROUNDS)
    bar = progress_bar(
        1 + len(sizes) * rounds + len(plan.get("first_frames", wanted)), "bench render: sessions"
    )
    try:
        return run_sessions(
            gl, by_id, ctx.quick, structures=wanted, progress=lambda what: bar.update(1), **plan
        )
    finally:
        bar.close()


def markdown(d: dict) -> str:
    base = d["structures"][0]
    lines = [
        "**Session frames by structure** (the demo's scan, the workspace view as `render "
        "--connect` draws it; "
        f"medians of {d['frames']} frames, {d['rounds']} round(s), every case's frames in turn; "
        f"ratios to {base.upper()} "
        f"of the same round: median [range]):",
        "",
        f"| structure | atoms | size | lighting | frame (ms) | CPU (ms) | / {base.upper()} (CPU) | "
        f"/ {base.upper()} (wall) "
        "| lit / unlit (CPU) | layer kept | first frame in process (s) | `--frames 1` wall (CPU) "
        "(s) |",
        "|---|---:|---|---|---:|---:|---:|---:|---:|---:|---:|---:|",
    ]
    for r in d["rows"]:
        lo, hi = r[f"over_{base}_cpu_range"]
        wlo, whi = r[f"over_{base}_range"]
        lit = f"{r['lit_over_unlit_cpu']:.2f}" if r["lighting"] == "lit" else ""
        first = (
            f"{r['connect_frames_1_s']:.2f} ({r['connect_frames_1_cpu_s']:.2f})"
            if "connect_frames_1_s" in r and r["lighting"] == "lit"
            else ""
        )
        lines.append(
            f"| {r['id']} | {r['atoms']} | {r['size'][0]}x{r['size'][1]} | {r['lighting']} | "
            f"{r['ms']:.1f} | "
            f"{r['cpu_ms']:.1f} | {r[f'over_{base}_cpu']:.2f} [{lo:.2f}–{hi:.2f}] | "
            f"{r[f'over_{base}']:.2f} "
            f"[{wlo:.2f}–{whi:.2f}] | {lit} | {r['kept']}/{r['frames']} | {r['first_frame_s']:.2f} "
            f"| {first} |"
        )
    lines += [
        "",
        "`--frames 1`: the default lighting, process start to exit, the daemon already running; in "
        "brackets the process's CPU time (llvmpipe's threads included), which other work on the "
        "machine "
        f"does not stretch. Load average before and after: {d['load'][0]:.1f}, {d['load'][1]:.1f}.",
    ]
    return "\n".join(lines)


def chart(d: dict, path, renderer_name: str):
    """Session frame CPU time by structure (unlit and lit, each size), and `--frames 1` wall
    time."""
    from sasprobe.cli.bench.charts import pyplot, save

    ids = d["structures"]
    fig, axes = pyplot().subplots(1, 2, figsize=(11, 3.8), dpi=110)
    width = 0.8 / (len(d["sizes"]) * len(LIGHTINGS))
    x = np.arange(len(ids))
    k = 0
    for size in d["sizes"]:
        for lighting in LIGHTINGS:
            values = [
                next(
                    r["cpu_ms"]
                    for r in d["rows"]
                    if r["id"] == sid and r["size"] == size and r["lighting"] == lighting
                )
                for sid in ids
            ]
            axes[0].bar(
                x + (k - (len(d["sizes"]) * len(LIGHTINGS) - 1) / 2) * width,
                values,
                width,
                label=f"{lighting}, {size[0]}x{size[1]}",
            )
            k += 1
    axes[0].set_xticks(
        x, [f"{sid}\n{next(r['atoms'] for r in d['rows'] if r['id'] == sid)} atoms" for sid in ids]
    )
    axes[0].set_ylabel("median session frame, CPU ms")
    axes[0].set_ylim(top=axes[0].get_ylim()[1] * 1.3)  # room for the legend above the bars
    axes[0].legend(fontsize=7, ncol=2, loc="upper center")
    axes[0].set_title(f"Session frame by structure\n{renderer_name.split(' / ')[0]}", fontsize=9)
    if all("connect_frames_1_s" in r for r in d["rows"]):
        for size in d["sizes"]:
            for key, style, what in (
                ("connect_frames_1_s", "o-", "wall"),
                ("connect_frames_1_cpu_s", "s--", "CPU"),
            ):
                axes[1].plot(
                    ids,
                    [
                        next(r[key] for r in d["rows"] if r["id"] == sid and r["size"] == size)
                        for sid in ids
                    ],
                    style,
                    label=f"{size[0]}x{size[1]}, {what}",
                )
        axes[1].axhline(3.0, color="grey", lw=0.8, ls=":", label="3 s goal")
        axes[1].set_ylabel("render --connect --frames 1, s")
        axes[1].set_ylim(bottom=0)
        axes[1].legend(fontsize=7)
        axes[1].set_title("Time to the first frame (process start included)", fontsize=9)
    else:
        axes[1].axis("off")
    return save(fig, Path(path))
