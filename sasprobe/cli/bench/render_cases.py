"""What the render benchmarks time, and how: a case (a renderer, its camera and the step
that moves its scene before each frame), the frames of several cases taken in turn (so load
from other processes falls on all of them alike), the demo's path of poses, and a navigation
cube holding a given number of atoms."""

from __future__ import annotations

import os
import statistics
import time
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

PATH_FPS = 30.0  # poses per second of the demo path (a renderer's frame rate)
# The session simulated; the frames are its first stretch in contact at least half the time.
PATH_SEARCH_S = 8.0
CUBE_TARGET_ATOMS = 300  # the navigation cube the benchmarks draw holds about this many atoms


@dataclass
class Case:
    label: str
    renderer: object
    camera: object
    step: Callable[[int], None]  # before frame k: move what the scenario moves
    times: list[float] = field(default_factory=list)  # wall seconds per frame
    cpu: list[float] = field(default_factory=list)  # CPU seconds of this process per frame


def load_average() -> float:
    return round(os.getloadavg()[0], 2)


def demo_path(structure, frames: int, cube=None) -> list:
    """Poses of the demo's session (sim:scan through the haptic engine), one per 1/PATH_FPS s:
    the first `frames` of them in contact at least half the time (the probe comes in, touches
    and slides; how soon depends on the structure). The workspace is mapped onto `cube` (a
    NavCube) when given, else the demo's own."""
    from sasprobe.cli.bench.haptics import closed_loop_session
    from sasprobe.devices.base import PHANTOM_OMNI_LIMITS

    stride = int(1000 / PATH_FPS)
    mapping = {} if cube is None else {"cube_half_A": cube.half, "cube_center_A": cube.center}
    _, outputs, _ = closed_loop_session(
        structure,
        "scan",
        "proxy",
        mapping,
        PHANTOM_OMNI_LIMITS,
        int(PATH_SEARCH_S * 1000) + stride * frames,
    )
    poses = outputs[::stride]
    contact = np.convolve([p.contact for p in poses], np.ones(frames) / frames, mode="valid")
    start = int(np.argmax(contact >= 0.5)) if np.any(contact >= 0.5) else int(np.argmax(contact))
    return poses[start : start + frames]


def first_cube(path):
    from sasprobe.render.scene_state import NavCube

    return NavCube(np.array(path[0].cube_center_A, dtype=np.float64), float(path[0].cube_half_A))


def follow_path(scene, path, with_cube: bool = True) -> Callable[[int], None]:
    """The step that puts pose k of the path into the scene: probe, touched atom and (with
    `with_cube`) the navigation cube."""
    from sasprobe.render.scene_state import NavCube, Probe

    def step(k: int) -> None:
        pose = path[k % len(path)]
        scene.probe = Probe(
            center=np.array(pose.proxy_A, dtype=np.float64),
            touched_atom=pose.touched_atoms[0] if pose.touched_atoms else -1,
        )
        if not with_cube:
            return
        center = np.array(pose.cube_center_A, dtype=np.float64)
        if (
            not np.array_equal(center, scene.nav_cube.center)
            or pose.cube_half_A != scene.nav_cube.half
        ):
            scene.nav_cube = NavCube(center, float(pose.cube_half_A))

    return step


def make_case(gl, label: str, structure, size, lighting, cache: bool, nav_cube=None, camera=None):
    from sasprobe.render.camera import Camera
    from sasprobe.render.renderer import Renderer
    from sasprobe.render.scene_state import SceneState

    scene = SceneState(structure, nav_cube=nav_cube)
    if lighting is not None:
        for name, on in lighting.effects().items():
            setattr(scene.effects, name, on)
    renderer = Renderer(gl, scene, size, frame_cache=cache)
    if lighting is not None:
        renderer.install_lighting(lighting)
    if camera is None:
        center, radius = scene.bounding_sphere()
        camera = Camera.fitted(center, radius, size[0] / size[1])
    return Case(
        label, renderer, Camera(camera.eye, camera.target, camera.up, camera.fov_y), lambda k: None
    )


def time_cases(gl, cases: list[Case], frames: int, warmup: int = 2) -> None:
    """Frame k of every case, in turn, for k < frames (after `warmup` frames each, whose
    steps are those of frames 0..warmup-1 again)."""
    for k in range(warmup):
        for case in cases:
            case.step(k)
            case.renderer.render(case.camera)
    gl.finish()
    for k in range(frames):
        for case in cases:
            case.step(k)
            gl.finish()
            t0, c0 = time.perf_counter(), time.process_time()
            case.renderer.render(case.camera)
            gl.finish()
            case.times.append(time.perf_counter() - t0)
            case.cpu.append(time.process_time() - c0)


def summary(cases: list[Case], unlit: str, full: str) -> dict:
    rows = {}
    for case in cases:
        counts = case.renderer.planner.layer_counts() if case.renderer.planner is not None else None
        rows[case.label] = {
            "ms": statistics.median(case.times) * 1e3,
            "cpu_ms": statistics.median(case.cpu) * 1e3,
            "frames": len(case.times),
            "cache_hits": None if counts is None else counts["kept"],
            "cache_misses": None if counts is None else counts["drawn"],
        }
    for row in rows.values():
        for key, suffix in (("ms", ""), ("cpu_ms", "_cpu")):
            row["over_unlit" + suffix] = row[key] / rows[unlit][key]
            row["full_over_this" + suffix] = rows[full][key] / row[key]
    return rows


def release(cases: list[Case]) -> None:
    for case in cases:
        case.renderer.release()


def cube_for(structure, target: int):
    """A navigation cube around the atom nearest the centroid holding about `target`
    atoms (half edge found by bisection)."""
    from sasprobe.render.scene_state import NavCube

    pos, radii = structure.positions, structure.vdw_radii
    center = pos[np.argmin(np.linalg.norm(pos - pos.mean(axis=0), axis=1))].copy()

    def count(half: float) -> int:
        gap = pos - np.clip(pos, center - half, center + half)
        return int(np.count_nonzero(np.einsum("ij,ij->i", gap, gap) <= radii**2))

    lo, hi = 0.5, 50.0
    for _ in range(40):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if count(mid) < target else (lo, mid)
    return NavCube(center=center, half=hi), count(hi)
