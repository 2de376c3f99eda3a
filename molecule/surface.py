"""Column queries on a molecule's solvent accessible surface, and where a session starts on it.

The expanded spheres (vdW + probe radius) through the uniform grid: the solid intervals
of a vertical column (molecule z), the top of the surface above a point, and the
surface site a zoomed-in navigation cube starts on. Shared by the workspace mapping (its
initial centre, devices/workspace/start.py) and the simulated arm's hand paths, so both
put the session in the same place.
"""

from __future__ import annotations

import numpy as np
from sasprobe.molecule.grid import UniformGrid
from sasprobe.molecule.probe import DEFAULT_PROBE_RADIUS

HEIGHT_SPACING_A = 2.0  # column spacing of the height map
SITE_BAND_A = 10.0  # the start site is within this of the molecule's highest point
SITE_CANDIDATES = 1024  # columns tried for it
SUMMIT_TOLERANCE_A = 2.0  # how much higher the surface may rise within the cube's footprint


class Surface:
    """Column queries on the expanded spheres of a grid (molecule frame, Å)."""

    def __init__(self, grid: UniformGrid):
        self.grid = grid
        self.zlo = float(grid.origin[2])
        self.zhi = float(grid.upper[2])

    @classmethod
    def of(cls, structure, probe_radius: float = DEFAULT_PROBE_RADIUS) -> Surface:
        return cls(UniformGrid(structure.positions, structure.expanded_radii(probe_radius)))

    def intervals(self, x: float, y: float) -> list[tuple[float, float, list[int]]]:
        """Solid intervals along z of the column at (x, y), top first: (z_low, z_high, atoms)."""
        cand = self.grid.candidates_in_box((x, y, self.zlo), (x, y, self.zhi))
        if cand.size == 0:
            return []
        c = self.grid.centers[cand]
        h2 = self.grid.radii[cand] ** 2 - (c[:, 0] - x) ** 2 - (c[:, 1] - y) ** 2
        keep = h2 > 0
        if not np.any(keep):
            return []
        half = np.sqrt(h2[keep])
        lows, highs, atoms = c[keep, 2] - half, c[keep, 2] + half, cand[keep]
        order = np.argsort(-highs, kind="stable")
        merged: list[tuple[float, float, list[int]]] = []
        for i in order:
            lo, hi = float(lows[i]), float(highs[i])
            if merged and hi >= merged[-1][0]:
                top_lo, top_hi, members = merged[-1]
                merged[-1] = (min(top_lo, lo), top_hi, members + [int(atoms[i])])
            else:
                merged.append((lo, hi, [int(atoms[i])]))
        return merged

    def top(self, x: float, y: float) -> float | None:
        cols = self.intervals(x, y)
        return cols[0][1] if cols else None

    def heights(
        self, spacing: float = HEIGHT_SPACING_A
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Height map of the surface seen from +z: (xs, ys, top) with top[i, j] the highest
        point of the expanded spheres over column (xs[i], ys[j]), NaN where the column is empty."""
        c, r = self.grid.centers, self.grid.radii
        lo, hi = (c[:, :2] - r[:, None]).min(axis=0), (c[:, :2] + r[:, None]).max(axis=0)
        xs = np.arange(lo[0], hi[0] + spacing, spacing)
        ys = np.arange(lo[1], hi[1] + spacing, spacing)
        top = np.full((xs.size, ys.size), -np.inf)
        reach = int(np.ceil(float(r.max()) / spacing))
        i0 = np.rint((c[:, 0] - xs[0]) / spacing).astype(np.int64)
        j0 = np.rint((c[:, 1] - ys[0]) / spacing).astype(np.int64)
        # every column within reach of each atom, vectorised per offset
        for di in range(-reach, reach + 1):
            for dj in range(-reach, reach + 1):
                i, j = i0 + di, j0 + dj
                ok = (i >= 0) & (i < xs.size) & (j >= 0) & (j < ys.size)
                h2 = r[ok] ** 2 - (xs[i[ok]] - c[ok, 0]) ** 2 - (ys[j[ok]] - c[ok, 1]) ** 2
                inside = h2 > 0
                np.maximum.at(
                    top, (i[ok][inside], j[ok][inside]), c[ok, 2][inside] + np.sqrt(h2[inside])
                )
        top[~np.isfinite(top)] = np.nan
        return xs, ys, top

    def site(self, half: float) -> tuple[float, float, float]:
        """Where a zoomed-in cube of half edge `half` starts: the summit nearest the molecule's
        x-y middle, a summit being a column within SITE_BAND_A of the highest point that
        nothing in the cube's footprint overtops by more than SUMMIT_TOLERANCE_A."""
        # +z faces the viewer at the start. The top of a molecule is its outside, so the site
        # is never in a cavity nor in empty space; on a summit the cube has room to hover and
        # the camera above sees the surface, not cut atoms.
        xs, ys, top = self.heights()
        ii, jj = np.nonzero(np.isfinite(top) & (top >= np.nanmax(top) - SITE_BAND_A))
        if ii.size > SITE_CANDIDATES:
            keep = np.linspace(0, ii.size - 1, SITE_CANDIDATES).astype(np.int64)
            ii, jj = ii[keep], jj[keep]
        spacing = float(xs[1] - xs[0]) if xs.size > 1 else HEIGHT_SPACING_A
        reach = int(np.ceil(half / spacing))
        filled = np.where(np.isfinite(top), top, -np.inf)
        excess = np.array(
            [
                np.max(filled[max(i - reach, 0) : i + reach + 1, max(j - reach, 0) : j + reach + 1])
                - top[i, j]
                for i, j in zip(ii, jj)
            ]
        )
        summit = excess <= SUMMIT_TOLERANCE_A
        if not np.any(summit):  # cannot happen (the highest column is a summit), but never fail
            summit = excess <= excess.min()
        ii, jj = ii[summit], jj[summit]
        c = self.grid.centers
        mid = (c.min(axis=0) + c.max(axis=0)) / 2.0
        k = int(np.argmin((xs[ii] - mid[0]) ** 2 + (ys[jj] - mid[1]) ** 2))
        x, y = float(xs[ii[k]]), float(ys[jj[k]])
        return x, y, float(self.top(x, y))


def surface_site(
    structure, half: float, probe_radius: float = DEFAULT_PROBE_RADIUS
) -> tuple[float, float, float]:
    """Surface.site(half) of a structure (builds its grid)."""
    return Surface.of(structure, probe_radius).site(half)
