"""Scenes the lighting benchmark measures: a grid on the GPU, a camera and a G-buffer traced
through the grid (so the lighting passes can be timed without the impostor pipeline)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from sasprobe.cli.bench.charts import figure, save
from sasprobe.molecule import DEFAULT_PROBE_RADIUS, UniformGrid
from sasprobe.render.camera import Camera, fit_bounding_sphere
from sasprobe.render.lighting.culling import Culling
from sasprobe.render.lighting.gbuffer import GBuffer, RaycastGBuffer
from sasprobe.render.lighting.uploaded_grid import UploadedGrid

VIEW_DIRECTION = (0.3, 0.4, 1.0)


def gl_context():
    import moderngl

    return moderngl.create_standalone_context(backend="egl", require=430)


SLOW_SECONDS = 2.0  # a call slower than this is timed in fewer rounds


def interleaved_times(gl, calls: dict, repeats: int) -> dict:
    """Median seconds of each call (GPU drained after each), measured round-robin: one call
    of each per round, so load from elsewhere on the machine (llvmpipe shares the CPU)
    falls on all of them alike and their ratios stay fair. One warm-up call each; calls
    slower than SLOW_SECONDS take part in at most 3 rounds."""
    import statistics
    import time

    def timed(fn) -> float:
        t0 = time.perf_counter()
        fn()
        gl.finish()
        return time.perf_counter() - t0

    warm = {key: timed(fn) for key, fn in calls.items()}
    samples = {key: [] for key in calls}
    for round_ in range(max(1, repeats)):
        for key, fn in calls.items():
            if round_ < 3 or warm[key] < SLOW_SECONDS:
                samples[key].append(timed(fn))
    return {key: statistics.median(v) for key, v in samples.items()}


def gpu_time(gl, fn, repeats: int) -> float:
    """Median seconds of fn() with the GPU drained after each call."""
    return interleaved_times(gl, {0: fn}, repeats)[0]


@dataclass
class Scene:
    grid: UploadedGrid
    view: np.ndarray
    proj: np.ndarray
    gbuffer: GBuffer
    atom: np.ndarray  # G-buffer atom ids (row 0 = bottom)

    @property
    def coverage(self) -> float:
        return float((self.atom != -1).mean())

    @property
    def eye(self) -> np.ndarray:
        return np.linalg.inv(self.view)[:3, 3]

    def release(self) -> None:
        self.gbuffer.release()


def spheres_grid(gl, centers, radii, cell_size: float | None = None) -> UploadedGrid:
    centers = np.asarray(centers, dtype=np.float64)
    radii = np.asarray(radii, dtype=np.float64)
    return UploadedGrid(gl, UniformGrid(centers, radii + DEFAULT_PROBE_RADIUS, cell_size), radii)


def trace_scene(grid: UploadedGrid, view, proj, size: tuple[int, int]) -> Scene:
    caster = RaycastGBuffer(grid)
    gbuffer = caster.render(view, proj, *size)
    caster.release()
    return Scene(grid, view, proj, gbuffer, gbuffer.download()[2])


def fitted_scene(
    grid: UploadedGrid, size: tuple[int, int], fill: float = 1.0, culling: Culling | None = None
) -> Scene:
    """The molecule's bounding sphere (or the navigation cube's) filling `fill` of the view."""
    grid.set_culling(culling or Culling())
    box = grid.culling.cube_box
    if box is None:
        centers, radii = grid.grid.centers, grid.vdw_radii
    else:  # frame the cube: its corners as zero-radius points
        corners = np.array(np.meshgrid(*zip(box[0], box[1]), indexing="ij")).reshape(3, -1).T
        centers, radii = corners, np.zeros(8)
    view, proj = fit_bounding_sphere(centers, radii, size[0] / size[1], VIEW_DIRECTION, fill=fill)
    return trace_scene(grid, view, proj, size)


def scene_with_coverage(
    grid: UploadedGrid, size: tuple[int, int], target: float, culling: Culling | None = None
) -> Scene:
    """A fitted scene zoomed until about `target` of the pixels show the molecule (equal
    screen coverage makes per-frame times of different molecules comparable)."""
    fill = 1.0
    scene = fitted_scene(grid, size, fill, culling)
    for _ in range(3):
        if abs(scene.coverage - target) < 0.03 or scene.coverage == 0:
            break
        fill *= float(np.sqrt(target / scene.coverage))
        scene.release()
        scene = fitted_scene(grid, size, fill, culling)
    return scene


def oblique_camera(
    target, distance: float, elevation_deg: float, size: tuple[int, int], fov: float = 40.0
):
    el = np.radians(elevation_deg)
    eye = np.asarray(target, dtype=np.float64) + distance * np.array([0.0, -np.cos(el), np.sin(el)])
    camera = Camera(eye, target, up=(0.0, 0.0, 1.0), fov_y=fov, near=1.0, far=distance * 4)
    return camera.view(), camera.projection(size[0] / size[1])


def cost_vs_size_chart(
    rows: list[dict], series: list[tuple[str, str, str]], title: str, ylabel: str, path
):
    """Time against atom count on log axes, with a ±20 % band around the first structure's
    value of the first series (the flatness target). series: (row key, label, style)."""
    fig, ax = figure()
    atoms = [r["atoms"] for r in rows]
    base = rows[0][series[0][0]]
    ax.fill_between(
        [min(atoms), max(atoms)],
        base * 0.8,
        base * 1.2,
        color="tab:blue",
        alpha=0.12,
        label=f"±20 % of {rows[0]['structure']}",
    )
    for key, label, style in series:
        ax.plot(atoms, [r[key] for r in rows], style, label=label)
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel("atoms in the structure (about half the pixels show atoms)")
    ax.set_ylabel(ylabel)
    ax.set_title(title)
    ax.legend(fontsize=7)
    return save(fig, path)
