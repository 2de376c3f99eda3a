"""`sasprobe bench grid`: load and grid-build time, memory and occupancy per reference structure."""

from __future__ import annotations

import numpy as np

from sasprobe.cli.bench import BenchContext, BenchResult, median_time
from sasprobe.cli.bench.charts import times_vs_atoms
from sasprobe.cli.reference_data import MISSING, reference_structures
from sasprobe.common.errors import UserError
from sasprobe.common.progress import progress
from sasprobe.molecule import DEFAULT_PROBE_RADIUS, UniformGrid, load_default, load_structure

TITLE = "Structure loading and uniform grid"


def run(ctx: BenchContext) -> BenchResult:
    entries = reference_structures()
    if not entries:
        raise UserError(MISSING)
    if ctx.smoke:
        entries = entries[:1]
    load_repeats, grid_repeats, query_points = (
        (1, 1, 20) if ctx.smoke else (1, 3, 200) if ctx.quick else (3, 7, 2000)
    )
    rng = np.random.default_rng(7)
    rows = []
    for entry in progress(entries, desc="bench grid", total=len(entries)):
        structure = load_structure(entry.path)
        load_s = median_time(lambda path=entry.path: load_structure(path), load_repeats)
        radii = structure.expanded_radii(DEFAULT_PROBE_RADIUS)
        grid_s = median_time(lambda p=structure.positions, r=radii: UniformGrid(p, r), grid_repeats)
        grid = UniformGrid(structure.positions, radii)
        # Neighbour query the haptic loop makes: spheres within one probe radius of
        # points near the surface (random atoms, offset by their expanded radius).
        picks = rng.integers(0, structure.n_atoms, query_points)
        dirs = rng.normal(size=(query_points, 3))
        dirs /= np.linalg.norm(dirs, axis=1)[:, None]
        points = structure.positions[picks] + dirs * radii[picks, None]
        query_s = median_time(
            lambda grid=grid, points=points: [
                grid.spheres_within(p, DEFAULT_PROBE_RADIUS) for p in points
            ],
            3,
        )
        rows.append(
            {
                "id": entry.id,
                "format": entry.format,
                "n_atoms": structure.n_atoms,
                "load_s": load_s,
                "grid_s": grid_s,
                "grid_s_per_100k": grid_s / structure.n_atoms * 1e5,
                "load_plus_grid_s": load_s + grid_s,
                "query_us": query_s / query_points * 1e6,
                "grid": grid.stats().as_dict(),
            }
        )
    default_s = median_time(load_default, load_repeats)
    charts = []
    path = ctx.chart_path("grid_build.png")
    if path is not None:
        series = [
            ([r["load_s"] for r in rows], "o-", "load (gemmi + arrays)"),
            ([r["grid_s"] for r in rows], "s-", "grid build"),
        ]
        title = "Load and grid build time vs structure size"
        charts.append(times_vs_atoms(path, [r["n_atoms"] for r in rows], series, title))
    lines = [
        "| structure | atoms | load (ms) | grid (ms) | grid per 100k atoms (ms) | query (µs) | "
        "cells | non-empty | max/cell | mean/non-empty | grid KiB |",
        "|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|",
    ]
    for r in rows:
        g = r["grid"]
        lines.append(
            f"| {r['id']} ({r['format']}) | {r['n_atoms']} | {r['load_s'] * 1e3:.1f} | "
            f"{r['grid_s'] * 1e3:.2f} | "
            f"{r['grid_s_per_100k'] * 1e3:.1f} | {r['query_us']:.1f} | {g['n_cells']} | "
            f"{g['n_nonempty']} | "
            f"{g['max_per_cell']} | {g['mean_per_nonempty']:.1f} | {g['bytes'] / 1024:.0f} |"
        )
    markdown = (
        f"Medians over {load_repeats} loads and {grid_repeats} grid builds per structure "
        f"(probe 1.4 Å, default cell edge = largest expanded diameter). 'query' is one "
        "`spheres_within(point, 1.4 Å)` near the surface. Embedded 1CRN loads in "
        f"{default_s * 1e3:.1f} ms.\n\n" + "\n".join(lines)
    )
    return BenchResult("grid", {"structures": rows, "embedded_load_s": default_s}, markdown, charts)
