"""Shadow part of `sasprobe bench lighting`: time and grid memory against the number of
cells (cell-size sweep down to one cell = brute force), soft over hard, shadows bounded
by the navigation cube against molecule size, and the probe light's shadows through the
grid walk against its light buffer (render/lighting/light_buffer.py)."""

from __future__ import annotations

import numpy as np

from sasprobe.cli.bench.lighting_scene import (
    cost_vs_size_chart,
    fitted_scene,
    interleaved_times,
    scene_with_coverage,
)
from sasprobe.molecule import DEFAULT_PROBE_RADIUS, UniformGrid
from sasprobe.render.gl.textures import read_texture
from sasprobe.render.lighting.culling import Culling
from sasprobe.render.lighting.settings import (
    DEFAULT_PROBE_RANGE,
    HARD_SHADOW,
    DirectionalLight,
    PointLight,
    SoftShadow,
)
from sasprobe.render.lighting.shadows import ShadowTracer
from sasprobe.render.lighting.uploaded_grid import UploadedGrid

SUN = DirectionalLight((0.45, 0.8, 0.4))
SOFT = SoftShadow()
CUBE_HALF = 9.0  # Å: a navigation cube holding a few hundred atoms
COVERAGE = 0.5  # of the pixels showing atoms, for scenes compared across molecules
CUBE_SERIES = [  # (row key, label, line style) of cube_chart
    ("cube_hard_ms", "cube on: hard", "o-"),
    ("cube_soft_ms", "cube on: soft", "x-"),
    ("whole_hard_ms", "whole molecule: hard", "s--"),
]


def densest_cube_centre(grid: UploadedGrid, candidates: int = 64, seed: int = 3) -> np.ndarray:
    """Centre of a navigation cube inside the protein: of a few random atoms, the one whose
    cube holds the most atoms (the centroid of a hollow assembly such as GroEL is empty)."""
    rng = np.random.default_rng(seed)
    centers = grid.grid.centers
    picks = centers[rng.choice(centers.shape[0], min(candidates, centers.shape[0]), replace=False)]
    counts = [grid.grid.spheres_in_box(c - CUBE_HALF, c + CUBE_HALF).size for c in picks]
    return picks[int(np.argmax(counts))]


def cell_sweep(gl, name: str, structure, size, cell_sizes, repeats: int) -> list[dict]:
    """Hard and soft directional shadows of one view for each cell size; the last grid has
    a single cell (every ray tests every atom: brute force)."""
    expanded = structure.expanded_radii(DEFAULT_PROBE_RADIUS)
    default = UploadedGrid(gl, UniformGrid(structure.positions, expanded), structure.vdw_radii)
    scene = fitted_scene(default, size, fill=1.0)
    extent = float(np.max(default.grid.upper - default.grid.origin))
    grids = [
        default
        if cell is None
        else UploadedGrid(gl, UniformGrid(structure.positions, expanded, cell), structure.vdw_radii)
        for cell in [*cell_sizes, None, extent + 1.0]
    ]
    passes = [ShadowTracer(grid) for grid in grids]
    calls = {}
    for i, shadows in enumerate(passes):
        calls[(i, "hard_ms")] = lambda p=shadows: p.trace(scene.gbuffer, SUN, HARD_SHADOW)
        calls[(i, "soft_ms")] = lambda p=shadows: p.trace(scene.gbuffer, SUN, SOFT)
    seconds = interleaved_times(gl, calls, repeats)
    rows = []
    for i, grid in enumerate(grids):
        stats = grid.grid.stats()
        rows.append(
            {
                "structure": name,
                "atoms": structure.n_atoms,
                "cell_size": stats.cell_size,
                "cells": stats.n_cells,
                "default": grid is default,
                "brute_force": stats.n_cells == 1,
                "grid_bytes": grid.nbytes,
                "hard_ms": seconds[(i, "hard_ms")] * 1e3,
                "soft_ms": seconds[(i, "soft_ms")] * 1e3,
            }
        )
    for shadows, grid in zip(passes, grids):
        shadows.release()
        grid.release()
    scene.release()
    return rows


def sweep_chart(rows: list[dict], path):
    from sasprobe.cli.bench.charts import pyplot, save

    fig, (ax, ax2) = pyplot().subplots(1, 2, figsize=(11, 4), dpi=110)
    for name in dict.fromkeys(r["structure"] for r in rows):
        pts = sorted((r for r in rows if r["structure"] == name), key=lambda r: r["cells"])
        atoms = pts[0]["atoms"]
        cells = [r["cells"] for r in pts]
        (line,) = ax.loglog(
            cells, [r["hard_ms"] for r in pts], "o-", label=f"{name} ({atoms} atoms) hard"
        )
        ax.loglog(
            cells, [r["soft_ms"] for r in pts], "x:", color=line.get_color(), label=f"{name} soft"
        )
        default = next(r for r in pts if r["default"])
        ax.scatter(
            [default["cells"]],
            [default["hard_ms"]],
            s=120,
            facecolors="none",
            edgecolors="k",
            zorder=4,
        )
        ax2.loglog(
            cells, [r["grid_bytes"] / 2**20 for r in pts], "o-", color=line.get_color(), label=name
        )
    ax.set_xlabel("grid cells (1 = brute force)")
    ax.set_ylabel("shadow pass (ms, median)")
    ax.set_title("Directional shadows vs cell count (circle: default cell)", fontsize=9)
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=6)
    ax2.set_xlabel("grid cells")
    ax2.set_ylabel("GPU grid + sphere buffers (MiB)")
    ax2.set_title("Grid memory vs cell count", fontsize=9)
    ax2.grid(True, which="both", alpha=0.3)
    ax2.legend(fontsize=7)
    return save(fig, path)


def cube_bounded(gl, structures: list[tuple[str, object]], size, repeats: int) -> list[dict]:
    """Hard and soft directional shadows with the navigation cube on (camera framing the
    cube, atoms outside culled, rays limited to the cube) and, for contrast, of the whole
    molecule; both at equal screen coverage. Each structure has its own grid, so the
    culling (set when its scene is traced) stays as the cube scene left it."""
    setups, calls = [], {}
    for name, structure in structures:
        grid = UploadedGrid.from_structure(gl, structure, DEFAULT_PROBE_RADIUS)
        whole_grid = UploadedGrid.from_structure(gl, structure, DEFAULT_PROBE_RADIUS)
        whole = scene_with_coverage(whole_grid, size, COVERAGE)
        cube = scene_with_coverage(
            grid, size, COVERAGE, Culling(nav_cube=(densest_cube_centre(grid), CUBE_HALF))
        )
        cube_pass, whole_pass = ShadowTracer(grid), ShadowTracer(whole_grid)
        setups.append((name, structure, grid, whole_grid, whole, cube, cube_pass, whole_pass))
        calls[(name, "whole_hard_ms")] = lambda p=whole_pass, s=whole: p.trace(
            s.gbuffer, SUN, HARD_SHADOW
        )
        calls[(name, "cube_hard_ms")] = lambda p=cube_pass, s=cube: p.trace(
            s.gbuffer, SUN, HARD_SHADOW
        )
        calls[(name, "cube_soft_ms")] = lambda p=cube_pass, s=cube: p.trace(s.gbuffer, SUN, SOFT)
    seconds = interleaved_times(gl, calls, repeats)
    rows = []
    for name, structure, grid, whole_grid, whole, cube, cube_pass, whole_pass in setups:
        rows.append(
            {
                "structure": name,
                "atoms": structure.n_atoms,
                "whole_coverage": whole.coverage,
                "cube_atoms": int((~grid.culled_mask).sum()),
                "cube_coverage": cube.coverage,
                **{
                    key: seconds[(name, key)] * 1e3
                    for key in ("whole_hard_ms", "cube_hard_ms", "cube_soft_ms")
                },
            }
        )
        for thing in (whole, cube, cube_pass, whole_pass, grid, whole_grid):
            thing.release()
    return rows


def cube_chart(rows: list[dict], path):
    title = f"Shadows bounded by a {2 * CUBE_HALF:g} Å navigation cube"
    return cost_vs_size_chart(rows, CUBE_SERIES, title, "shadow pass (ms, median)", path)


# ------------------------------------------------------------------ the probe light
def probe_on_view(scene) -> np.ndarray:
    """Where the probe rests in a scene: touching the surface at the atom pixel nearest the
    middle of the view, its centre a probe radius out along the normal."""
    position, normal, atom = scene.gbuffer.download()
    rows, cols = np.nonzero(atom >= 0)
    h, w = atom.shape
    k = int(np.argmin((rows - h / 2) ** 2 + (cols - w / 2) ** 2))
    n = normal[rows[k], cols[k]] / np.linalg.norm(normal[rows[k], cols[k]])
    return position[rows[k], cols[k]].astype(np.float64) + n * DEFAULT_PROBE_RADIUS


def _walk_against_buffer(
    gl, scene, light, walk: ShadowTracer, listed: ShadowTracer, buffer, repeats: int
) -> dict:
    """`light`'s shadows through the walk and through `listed`'s buffer, hard and soft, timed
    in the same rounds; the buffer's build apart (its key dropped, as when the light moved);
    and the largest difference between the two (0: the same occluders)."""

    def build():
        buffer.key = None
        listed.trace(scene.gbuffer, light, HARD_SHADOW, rect=(0, 0, 1, 1))

    calls = {
        ("walk", "hard"): lambda: walk.trace(scene.gbuffer, light, HARD_SHADOW),
        ("walk", "soft"): lambda: walk.trace(scene.gbuffer, light, SOFT),
        ("buffer", "hard"): lambda: listed.trace(scene.gbuffer, light, HARD_SHADOW),
        ("buffer", "soft"): lambda: listed.trace(scene.gbuffer, light, SOFT),
        ("build", "hard"): build,
    }
    seconds = interleaved_times(gl, calls, repeats)
    difference = max(
        float(
            np.abs(
                read_texture(walk.trace(scene.gbuffer, light, soft))
                - read_texture(listed.trace(scene.gbuffer, light, soft))
            ).max()
        )
        for soft in (HARD_SHADOW, SOFT)
    )
    return {
        "walk_hard_ms": seconds[("walk", "hard")] * 1e3,
        "walk_soft_ms": seconds[("walk", "soft")] * 1e3,
        "buffer_hard_ms": seconds[("buffer", "hard")] * 1e3,
        "buffer_soft_ms": seconds[("buffer", "soft")] * 1e3,
        "build_ms": seconds[("build", "hard")] * 1e3,
        "max_difference": difference,
    }


def probe_light(gl, structures: list[tuple[str, object]], size, repeats: int) -> list[dict]:
    """The probe's point light (the default reach) at the surface in the middle of the view,
    at equal screen coverage: shadows through the grid walk and through the light buffer,
    hard and soft, timed in the same rounds; the light buffer's build (every frame the probe
    moves) apart; the largest difference between the two (0: the same occluders)."""
    rows = []
    for name, structure in structures:
        grid = UploadedGrid.from_structure(gl, structure, DEFAULT_PROBE_RADIUS)
        scene = scene_with_coverage(grid, size, COVERAGE)
        lamp = PointLight(tuple(probe_on_view(scene)), DEFAULT_PROBE_RANGE)
        walk, listed = ShadowTracer(grid, light_buffer=False), ShadowTracer(grid)
        buffer = listed.light_buffer
        # Build: as when the probe moved
        timed = _walk_against_buffer(gl, scene, lamp, walk, listed, buffer, repeats)
        counts = buffer.counts()
        lit = np.linalg.norm(scene.gbuffer.download()[0] - np.asarray(lamp.position), axis=-1)
        rows.append(
            {
                "structure": name,
                "atoms": structure.n_atoms,
                "coverage": scene.coverage,
                "pixels_in_reach": int(((scene.atom >= 0) & (lit <= lamp.radius)).sum()),
                "atoms_in_reach": buffer.atoms_in_reach,
                "mean_list": float(counts.mean()),
                "longest_list": int(counts.max()),
                **timed,
            }
        )
        for thing in (walk, listed, scene, grid):
            thing.release()
    return rows


def sun_light(gl, structures: list[tuple[str, object]], size, repeats: int) -> list[dict]:
    """The directional light at equal screen coverage: shadows through the grid walk and
    through its buffer across the light, hard and soft, timed in the same rounds; the
    buffer's build (every frame the light turns with the camera) apart; the largest
    difference between the two (0: the same occluders)."""
    rows = []
    for name, structure in structures:
        grid = UploadedGrid.from_structure(gl, structure, DEFAULT_PROBE_RADIUS)
        scene = scene_with_coverage(grid, size, COVERAGE)
        walk, listed = ShadowTracer(grid, light_buffer=False), ShadowTracer(grid)
        # Build: the light turned
        timed = _walk_against_buffer(gl, scene, SUN, walk, listed, listed.sun_buffer, repeats)
        rows.append(
            {
                "structure": name,
                "atoms": structure.n_atoms,
                "coverage": scene.coverage,
                "entries": listed.sun_buffer.entries,
                **timed,
            }
        )
        for thing in (walk, listed, scene, grid):
            thing.release()
    return rows


TIMING_COLUMNS = (
    "walk hard (ms) | buffer hard (ms) | walk soft (ms) | buffer soft (ms) | build (ms)"
)


def _timing_cells(r: dict) -> str:
    """A row's TIMING_COLUMNS (from _walk_against_buffer)."""
    return (
        f"{r['walk_hard_ms']:.1f} | {r['buffer_hard_ms']:.1f} | {r['walk_soft_ms']:.1f} | "
        f"{r['buffer_soft_ms']:.1f} | {r['build_ms']:.1f}"
    )


def _table(title: str, header: str, rows: list[dict], cells) -> list[str]:
    """A markdown table under a title: the header's columns, then `cells(row)` for each row."""
    rule = "|" + "---|" * (header.count("|") - 1)
    return [title, "", header, rule, *(cells(r) for r in rows)]


def _row(r: dict, before: list, after: list) -> str:
    """A row of both lights' tables: structure, atoms, `before`, the timings, `after`, the
    largest difference."""
    cells = [r["structure"], r["atoms"], *before, _timing_cells(r), *after]
    return "| " + " | ".join(map(str, cells)) + f" | {r['max_difference']:.0e} |"


def _walk_over_buffer(r: dict) -> str:
    return f"{r['walk_hard_ms'] / r['buffer_hard_ms']:.2f}×"


def _walk_over_buffer_and_build(r: dict) -> str:
    return f"{r['walk_hard_ms'] / (r['buffer_hard_ms'] + r['build_ms']):.2f}×"


def sun_light_markdown(rows: list[dict], size) -> list[str]:
    title = (
        "### The directional light's shadows: grid walk vs its buffer across the light "
        f"({size[0]}×{size[1]}; medians, same rounds)"
    )
    header = (
        f"| structure | atoms | entries | {TIMING_COLUMNS} | hard: walk / buffer | "
        "walk / (buffer + build) | largest difference |"
    )
    after = (_walk_over_buffer, _walk_over_buffer_and_build)
    return _table(title, header, rows, lambda r: _row(r, [r["entries"]], [f(r) for f in after]))


def probe_light_markdown(rows: list[dict], size) -> list[str]:
    title = (
        f"### The probe light's shadows: grid walk vs light buffer ({size[0]}×{size[1]}, "
        f"reach {DEFAULT_PROBE_RANGE:g} Å, the probe on the surface in the middle of the view; "
        "medians, same rounds)"
    )
    header = (
        "| structure | atoms | pixels in reach | atoms in reach | mean / longest list | "
        f"{TIMING_COLUMNS} | hard: walk / (buffer + build) | largest difference |"
    )

    def reach(r: dict) -> list:
        lists = f"{r['mean_list']:.1f} / {r['longest_list']}"
        return [r["pixels_in_reach"], r["atoms_in_reach"], lists]

    return _table(
        title, header, rows, lambda r: _row(r, reach(r), [_walk_over_buffer_and_build(r)])
    )
