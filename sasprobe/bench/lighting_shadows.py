"""Shadow part of `sasprobe bench lighting`: time and grid memory against the number of
cells (cell-size sweep down to one cell = brute force), soft over hard, and shadows bounded
by the navigation cube against molecule size."""

from __future__ import annotations

import numpy as np

from sasprobe.bench.lighting_scene import cost_vs_size_chart, fitted_scene, interleaved_times, scene_with_coverage
from sasprobe.molecule import DEFAULT_PROBE_RADIUS, UniformGrid
from sasprobe.render.lighting.grid import Culling, GpuGrid
from sasprobe.render.lighting.settings import HARD_SHADOW, DirectionalLight, SoftShadow
from sasprobe.render.lighting.shadows import ShadowPass

SUN = DirectionalLight((0.45, 0.8, 0.4))
SOFT = SoftShadow()
CUBE_HALF = 9.0  # Å: a navigation cube holding a few hundred atoms
COVERAGE = 0.5  # of the pixels showing atoms, for scenes compared across molecules


def densest_cube_centre(grid: GpuGrid, candidates: int = 64, seed: int = 3) -> np.ndarray:
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
    default = GpuGrid(gl, UniformGrid(structure.positions, expanded), structure.vdw_radii)
    scene = fitted_scene(default, size, fill=1.0)
    extent = float(np.max(default.grid.upper - default.grid.origin))
    grids = [default if cell is None else GpuGrid(gl, UniformGrid(structure.positions, expanded, cell),
                                                  structure.vdw_radii)
             for cell in [*cell_sizes, None, extent + 1.0]]
    passes = [ShadowPass(grid) for grid in grids]
    calls = {}
    for i, shadows in enumerate(passes):
        calls[(i, "hard_ms")] = lambda p=shadows: p.trace(scene.gbuffer, SUN, HARD_SHADOW)
        calls[(i, "soft_ms")] = lambda p=shadows: p.trace(scene.gbuffer, SUN, SOFT)
    seconds = interleaved_times(gl, calls, repeats)
    rows = []
    for i, grid in enumerate(grids):
        stats = grid.grid.stats()
        rows.append({
            "structure": name, "atoms": structure.n_atoms, "cell_size": stats.cell_size, "cells": stats.n_cells,
            "default": grid is default, "brute_force": stats.n_cells == 1, "grid_bytes": grid.nbytes,
            "hard_ms": seconds[(i, "hard_ms")] * 1e3, "soft_ms": seconds[(i, "soft_ms")] * 1e3,
        })
    for shadows, grid in zip(passes, grids):
        shadows.release()
        grid.release()
    scene.release()
    return rows


def sweep_chart(rows: list[dict], path):
    from sasprobe.bench.charts import pyplot

    plt = pyplot()

    fig, (ax, ax2) = plt.subplots(1, 2, figsize=(11, 4), dpi=110)
    for name in dict.fromkeys(r["structure"] for r in rows):
        pts = sorted((r for r in rows if r["structure"] == name), key=lambda r: r["cells"])
        atoms = pts[0]["atoms"]
        cells = [r["cells"] for r in pts]
        line, = ax.loglog(cells, [r["hard_ms"] for r in pts], "o-", label=f"{name} ({atoms} atoms) hard")
        ax.loglog(cells, [r["soft_ms"] for r in pts], "x:", color=line.get_color(), label=f"{name} soft")
        default = next(r for r in pts if r["default"])
        ax.scatter([default["cells"]], [default["hard_ms"]], s=120, facecolors="none", edgecolors="k", zorder=4)
        ax2.loglog(cells, [r["grid_bytes"] / 2**20 for r in pts], "o-", color=line.get_color(), label=name)
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
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)
    return path


def cube_bounded(gl, structures: list[tuple[str, object]], size, repeats: int) -> list[dict]:
    """Hard and soft directional shadows with the navigation cube on (camera framing the
    cube, atoms outside culled, rays limited to the cube) and, for contrast, of the whole
    molecule; both at equal screen coverage. Each structure has its own grid, so the
    culling (set when its scene is traced) stays as the cube scene left it."""
    setups, calls = [], {}
    for name, structure in structures:
        grid = GpuGrid.from_structure(gl, structure, DEFAULT_PROBE_RADIUS)
        whole_grid = GpuGrid.from_structure(gl, structure, DEFAULT_PROBE_RADIUS)
        whole = scene_with_coverage(whole_grid, size, COVERAGE)
        cube = scene_with_coverage(grid, size, COVERAGE, Culling(nav_cube=(densest_cube_centre(grid), CUBE_HALF)))
        cube_pass, whole_pass = ShadowPass(grid), ShadowPass(whole_grid)
        setups.append((name, structure, grid, whole_grid, whole, cube, cube_pass, whole_pass))
        calls[(name, "whole_hard_ms")] = lambda p=whole_pass, s=whole: p.trace(s.gbuffer, SUN, HARD_SHADOW)
        calls[(name, "cube_hard_ms")] = lambda p=cube_pass, s=cube: p.trace(s.gbuffer, SUN, HARD_SHADOW)
        calls[(name, "cube_soft_ms")] = lambda p=cube_pass, s=cube: p.trace(s.gbuffer, SUN, SOFT)
    seconds = interleaved_times(gl, calls, repeats)
    rows = []
    for name, structure, grid, whole_grid, whole, cube, cube_pass, whole_pass in setups:
        rows.append({
            "structure": name, "atoms": structure.n_atoms, "whole_coverage": whole.coverage,
            "cube_atoms": int((~grid.culled_mask).sum()), "cube_coverage": cube.coverage,
            **{key: seconds[(name, key)] * 1e3 for key in ("whole_hard_ms", "cube_hard_ms", "cube_soft_ms")},
        })
        for thing in (whole, cube, cube_pass, whole_pass, grid, whole_grid):
            thing.release()
    return rows


def cube_chart(rows: list[dict], path):
    series = [("cube_hard_ms", "cube on: hard", "o-"), ("cube_soft_ms", "cube on: soft", "x-"),
              ("whole_hard_ms", "whole molecule: hard", "s--")]
    return cost_vs_size_chart(rows, series, f"Shadows bounded by a {2 * CUBE_HALF:g} Å navigation cube",
                              "shadow pass (ms, median)", path)
