"""Uniform grid over spheres: the one acceleration structure of sasprobe.

The same grid serves the haptic neighbour queries, navigation-cube culling and the GPU
shadow/AO traversal (uploaded as two buffers), so what is felt and what is drawn are
the same spheres.

Layout (stable; the GPU shaders and the G-buffer tools rely on it):
- cells are half-open boxes [origin + i*h, origin + (i+1)*h) per axis, h = cell_size;
- the flat cell id is ix + nx * (iy + ny * iz) (x fastest);
- CSR storage: the spheres of cell c are cell_atoms[cell_start[c]:cell_start[c+1]],
  in increasing sphere index; cell_start has n_cells + 1 entries (uint32);
- a sphere is stored in every cell that its bounding box overlaps.

With the default cell edge (the largest sphere diameter) a sphere overlaps at most
2 cells per axis, so at most 8 cells.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from sasprobe.common.errors import UserError

MAX_CELLS = 1 << 27  # 134M cells (0.5 GiB of offsets): beyond this a cell size is a mistake


class GridTooLarge(UserError, ValueError):
    """Spheres spread so far (or cells so small) that the grid would not fit; one line."""


@dataclass(frozen=True)
class GridStats:
    cell_size: float
    dims: tuple[int, int, int]
    n_cells: int
    n_nonempty: int
    max_per_cell: int
    mean_per_nonempty: float
    bytes: int  # cell_start + cell_atoms, what a GPU upload costs

    def as_dict(self) -> dict:
        return {
            "cell_size": self.cell_size,
            "dims": list(self.dims),
            "n_cells": self.n_cells,
            "n_nonempty": self.n_nonempty,
            "max_per_cell": self.max_per_cell,
            "mean_per_nonempty": self.mean_per_nonempty,
            "bytes": self.bytes,
        }


class UniformGrid:
    """Spheres (centres, radii) binned into a uniform grid with CSR cell lists."""

    def __init__(self, centers: np.ndarray, radii: np.ndarray, cell_size: float | None = None):
        centers = np.ascontiguousarray(centers, dtype=np.float64).reshape(-1, 3)
        radii = np.ascontiguousarray(radii, dtype=np.float64).reshape(-1)
        if centers.shape[0] == 0:
            raise ValueError("a grid needs at least one sphere")
        if radii.shape[0] != centers.shape[0]:
            raise ValueError("one radius per centre is needed")
        if not (np.all(np.isfinite(centers)) and np.all(np.isfinite(radii)) and np.all(radii >= 0)):
            raise ValueError("centres and radii must be finite, radii non-negative")
        if cell_size is None:
            cell_size = default_cell_size(radii)
        cell_size = float(cell_size)
        if not np.isfinite(cell_size) or cell_size <= 0:
            raise ValueError(f"cell size must be a positive number of Å, got {cell_size}")
        self.centers = centers
        self.radii = radii
        self.cell_size = cell_size
        lo = (centers - radii[:, None]).min(axis=0)
        hi = (centers + radii[:, None]).max(axis=0)
        self.origin = lo
        # floor + 1 so that the far face of the bounds falls inside the last cell
        dims = np.floor((hi - lo) / cell_size).astype(np.int64) + 1
        n_cells = int(np.prod(dims))
        if n_cells > MAX_CELLS:
            extent = " x ".join(f"{v:.0f}" for v in hi - lo)
            raise GridTooLarge(
                f"the spheres span {extent} Å: {n_cells} grid cells of {cell_size:g} Å exceed the "
                f"limit of {MAX_CELLS} (atoms far apart, or too small a cell size)"
            )
        self.dims = dims
        self.n_cells = n_cells
        self.cell_start, self.cell_atoms = self._build()
        self._bins: tuple | None = None  # centres binned once, for the nearest-neighbour queries
        # Plain-Python copies for the per-tick query (see spheres_within).
        self._origin_xyz = tuple(float(v) for v in self.origin)
        self._dims_xyz = tuple(int(v) for v in self.dims)

    # ------------------------------------------------------------------ build
    def _build(self) -> tuple[np.ndarray, np.ndarray]:
        n, dims = self.centers.shape[0], self.dims
        lo_idx = self.cell_index(self.centers - self.radii[:, None])
        span = self.cell_index(self.centers + self.radii[:, None]) - lo_idx + 1  # cells per axis
        # The flat id is linear in (ix, iy, iz), so a sphere's cells are its first cell's id
        # plus a constant offset per (dx, dy, dz) "layer". With spheres sorted by first
        # cell, every layer comes out sorted, and merging the sorted layers (timsort finds
        # the runs) is the whole counting sort: no per-sphere Python loop.
        first = lo_idx[:, 0] + dims[0] * (lo_idx[:, 1] + dims[1] * lo_idx[:, 2])
        order = np.argsort(first, kind="stable")
        first_sorted, span_sorted = first[order], span[order]
        cells: list[np.ndarray] = []
        spheres: list[np.ndarray] = []
        max_span = span.max(axis=0)
        for dz in range(max_span[2]):
            in_z = span_sorted[:, 2] > dz
            for dy in range(max_span[1]):
                in_zy = in_z & (span_sorted[:, 1] > dy)
                for dx in range(max_span[0]):
                    layer = in_zy & (span_sorted[:, 0] > dx)
                    cells.append(first_sorted[layer] + (dx + dims[0] * (dy + dims[1] * dz)))
                    spheres.append(order[layer])
        cell = np.concatenate(cells)
        sphere = np.concatenate(spheres)
        merged = np.argsort(cell * n + sphere, kind="stable")  # (cell, sphere) keys are unique
        cell_atoms = sphere[merged].astype(np.uint32)
        counts = np.bincount(cell, minlength=self.n_cells)
        cell_start = np.zeros(self.n_cells + 1, dtype=np.uint32)
        np.cumsum(counts, out=cell_start[1:])
        return cell_start, cell_atoms

    # ------------------------------------------------------------ addressing
    def cell_index(self, points: np.ndarray) -> np.ndarray:
        """Integer cell coordinates (…, 3) of points, clamped into the grid."""
        idx = np.floor((np.asarray(points, dtype=np.float64) - self.origin) / self.cell_size)
        return np.clip(idx, 0, self.dims - 1).astype(np.int64)

    def flat_id(self, ijk: np.ndarray) -> np.ndarray:
        ijk = np.asarray(ijk, dtype=np.int64)
        return ijk[..., 0] + self.dims[0] * (ijk[..., 1] + self.dims[1] * ijk[..., 2])

    def atoms_in_cell(self, flat: int) -> np.ndarray:
        return self.cell_atoms[self.cell_start[flat] : self.cell_start[flat + 1]]

    @property
    def upper(self) -> np.ndarray:
        """Far corner of the grid (Å)."""
        return self.origin + self.dims * self.cell_size

    # ---------------------------------------------------------- box queries
    def cell_range(self, lo: np.ndarray, hi: np.ndarray) -> tuple[np.ndarray, np.ndarray] | None:
        """Inclusive cell index range (imin, imax) of the cells an axis-aligned box overlaps.

        A box [lo, hi] overlaps the half-open cell [a, a+h) when lo < a+h and hi >= a.
        Returns None when the box misses the grid or is empty.
        """
        lo = np.asarray(lo, dtype=np.float64)
        hi = np.asarray(hi, dtype=np.float64)
        if np.any(hi < lo):
            return None
        imin = np.floor((lo - self.origin) / self.cell_size).astype(np.int64)
        imax = np.floor((hi - self.origin) / self.cell_size).astype(np.int64)
        if np.any(imax < 0) or np.any(imin >= self.dims):
            return None
        return np.maximum(imin, 0), np.minimum(imax, self.dims - 1)

    def cells_in_range(self, imin: np.ndarray, imax: np.ndarray) -> np.ndarray:
        """Flat ids of all cells in an inclusive index range, x fastest."""
        iz, iy, ix = np.meshgrid(
            np.arange(imin[2], imax[2] + 1),
            np.arange(imin[1], imax[1] + 1),
            np.arange(imin[0], imax[0] + 1),
            indexing="ij",
        )
        return (ix + self.dims[0] * (iy + self.dims[1] * iz)).reshape(-1)

    def _gather(self, cells: np.ndarray) -> np.ndarray:
        """Concatenated sphere lists of the given cells (with repeats), no Python loop."""
        starts = self.cell_start[cells].astype(np.int64)
        lengths = self.cell_start[cells + 1].astype(np.int64) - starts
        total = int(lengths.sum())
        if total == 0:
            return np.empty(0, dtype=np.int64)
        offsets = np.repeat(starts - (np.cumsum(lengths) - lengths), lengths)
        return self.cell_atoms[offsets + np.arange(total)].astype(np.int64)

    def candidates_in_box(self, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
        """Sorted unique spheres stored in the cells a box overlaps (a superset of hits)."""
        rng = self.cell_range(lo, hi)
        if rng is None:
            return np.empty(0, dtype=np.int64)
        stored = self._gather(self.cells_in_range(*rng))
        n = self.centers.shape[0]
        # a few cells of many: sorting them is cheaper than a pass over all
        if stored.size * 16 < n:
            return np.unique(stored)
        seen = np.zeros(n, dtype=bool)
        seen[stored] = True
        return np.flatnonzero(seen)

    def spheres_in_box(self, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
        """Spheres that overlap the closed box [lo, hi] (exact sphere-box test)."""
        lo = np.asarray(lo, dtype=np.float64)
        hi = np.asarray(hi, dtype=np.float64)
        cand = self.candidates_in_box(lo, hi)
        c = self.centers[cand]
        nearest = np.clip(c, lo, hi)
        d2 = np.einsum("ij,ij->i", c - nearest, c - nearest)
        return cand[d2 <= self.radii[cand] ** 2]

    def spheres_within(self, point: np.ndarray, distance: float) -> np.ndarray:
        """Spheres whose surface is within `distance` of a point: |p - c| - r <= distance.

        Spheres containing the point are included (their signed distance is negative).
        This is the haptic loop's query, so the few-cell walk uses plain Python ints:
        for 3-vectors, numpy's per-call overhead would cost more than the arithmetic.
        """
        px, py, pz = (float(v) for v in np.asarray(point, dtype=np.float64).reshape(3))
        d = float(distance)
        h = self.cell_size
        ox, oy, oz = self._origin_xyz
        nx, ny, nz = self._dims_xyz
        x0, x1 = max(math.floor((px - d - ox) / h), 0), min(math.floor((px + d - ox) / h), nx - 1)
        y0, y1 = max(math.floor((py - d - oy) / h), 0), min(math.floor((py + d - oy) / h), ny - 1)
        z0, z1 = max(math.floor((pz - d - oz) / h), 0), min(math.floor((pz + d - oz) / h), nz - 1)
        if x0 > x1 or y0 > y1 or z0 > z1:
            return np.empty(0, dtype=np.int64)
        start, atoms = self.cell_start, self.cell_atoms
        pieces = []
        for iz in range(z0, z1 + 1):
            for iy in range(y0, y1 + 1):
                row = nx * (iy + ny * iz)
                a, b = int(start[row + x0]), int(start[row + x1 + 1])  # cells x0..x1 are contiguous
                if b > a:
                    pieces.append(atoms[a:b])
        if not pieces:
            return np.empty(0, dtype=np.int64)
        cand = np.concatenate(pieces) if len(pieces) > 1 else pieces[0]
        diff = self.centers[cand] - (px, py, pz)
        dist = np.sqrt(np.einsum("ij,ij->i", diff, diff))
        return np.unique(cand[dist - self.radii[cand] <= d]).astype(np.int64)

    # ---------------------------------------------------- nearest neighbours
    def _centre_bins(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Centres binned once, each sphere in exactly one cell (CSR over `order`).

        Returns (cell ijk per sphere, flat cell per sphere, spheres sorted by cell,
        spheres per cell, CSR offsets into the sorted spheres).
        """
        home = self.cell_index(self.centers)
        flat = self.flat_id(home)
        order = np.argsort(flat, kind="stable")
        counts = np.bincount(flat, minlength=self.n_cells)
        start = np.zeros(self.n_cells + 1, dtype=np.int64)
        np.cumsum(counts, out=start[1:])
        return home, flat, order, counts, start

    def nearest_neighbors(
        self, k: int, of: np.ndarray | None = None
    ) -> tuple[np.ndarray, np.ndarray]:
        """The k nearest other spheres of every sphere (or of the spheres `of`), by centre
        distance.

        Returns (indices, distances), each (N, k) (or (len(of), k), in the order of `of`),
        sorted by distance; rows are padded with -1 / inf when fewer than k other spheres
        exist. Ties break by index. Candidates come from a block of cells around each
        centre's cell, grown until the k-th distance is inside the block's guaranteed
        radius, so the result is exact.
        """
        n = self.centers.shape[0]
        if k <= 0:
            raise ValueError("k must be positive")
        asked = np.arange(n) if of is None else np.unique(np.asarray(of, dtype=np.int64))  # sorted
        out_idx = np.full((asked.size, k), -1, dtype=np.int64)  # a row per sphere asked for
        out_dist = np.full((asked.size, k), np.inf, dtype=np.float64)
        if self._bins is None:
            self._bins = self._centre_bins()
        home, home_flat, order, counts, start = self._bins
        pending = asked
        ring = 1
        while pending.size:
            pending_sorted = pending[np.argsort(home_flat[pending], kind="stable")]
            _, first = np.unique(home_flat[pending_sorted], return_index=True)
            groups = np.split(pending_sorted, first[1:])
            whole_grid = bool(np.all(ring >= self.dims))
            still: list[np.ndarray] = []
            for members in groups:
                ijk = home[members[0]]
                imin = np.maximum(ijk - ring, 0)
                imax = np.minimum(ijk + ring, self.dims - 1)
                block = self.cells_in_range(imin, imax)
                cand = np.concatenate([order[start[b] : start[b + 1]] for b in block if counts[b]])
                cand.sort()
                diff = self.centers[members][:, None, :] - self.centers[cand][None, :, :]
                d = np.sqrt(np.einsum("ijk,ijk->ij", diff, diff))
                d[members[:, None] == cand[None, :]] = np.inf  # not its own neighbour
                kk = min(k, cand.size - 1)
                rows = np.searchsorted(asked, members)
                if kk > 0:
                    # stable sort by distance keeps lower index first on ties
                    best = np.argsort(d, axis=1, kind="stable")[:, :kk]
                    out_idx[rows, :kk] = cand[best]
                    out_dist[rows, :kk] = np.take_along_axis(d, best, axis=1)
                if whole_grid:
                    continue
                # Exact only if the k-th neighbour lies within the block's guaranteed radius.
                guaranteed = ring * self.cell_size
                unsure = (kk < k) | (out_dist[rows, max(kk - 1, 0)] > guaranteed)
                if np.any(unsure):
                    still.append(members[unsure])
            pending = np.concatenate(still) if still else np.empty(0, dtype=np.int64)
            ring += 1
        if of is not None:
            rows = np.searchsorted(asked, np.asarray(of, dtype=np.int64))
            return out_idx[rows], out_dist[rows]
        return out_idx, out_dist

    def nearest_to_point(self, point, k: int) -> np.ndarray:
        """The k spheres whose centres are nearest `point`, nearest first, ties by index
        (-1 padded): the spheres within a distance doubled until k of them lie inside it."""
        point = np.asarray(point, dtype=np.float64).reshape(3)
        reach = float(
            np.linalg.norm(np.maximum(np.abs(point - self.origin), np.abs(point - self.upper)))
        )
        distance = self.cell_size
        while True:
            cand = self.spheres_within(point, distance)
            diff = self.centers[cand] - point
            dist = np.sqrt(np.einsum("ij,ij->i", diff, diff))
            if np.count_nonzero(dist <= distance) >= k or distance >= reach:
                break
            distance *= 2.0
        order = np.lexsort((cand, dist))[:k]
        out = np.full(k, -1, dtype=np.int64)
        out[: order.size] = cand[order]
        return out

    def overlapping_pairs(self) -> tuple[np.ndarray, np.ndarray]:
        """All ordered pairs (i, j), i != j, of overlapping spheres, sorted by i then j.

        Centres are binned once (one cell each); two spheres can only overlap when their
        centres are closer than the largest diameter, so comparing each cell with the
        cells within that reach finds every pair. Vectorised per neighbour offset.
        """
        n = self.centers.shape[0]
        _, _, order, counts, start = self._centre_bins()
        occupied = np.flatnonzero(counts)
        occ_ijk = np.stack(np.unravel_index(occupied, tuple(self.dims[::-1])), axis=1)[:, ::-1]
        reach = int(np.ceil(2.0 * self.radii.max() / self.cell_size))
        firsts: list[np.ndarray] = []
        seconds: list[np.ndarray] = []
        offsets = range(-reach, reach + 1)
        for dz in offsets:
            for dy in offsets:
                for dx in offsets:
                    if (dz, dy, dx) < (0, 0, 0):
                        continue  # each unordered cell pair once; pairs are mirrored below
                    other = occ_ijk + (dx, dy, dz)
                    ok = np.all((other >= 0) & (other < self.dims), axis=1)
                    a_cells = occupied[ok]
                    b_cells = self.flat_id(other[ok])
                    ca, cb = counts[a_cells], counts[b_cells]
                    per = ca * cb
                    if not per.any():
                        continue
                    total = int(per.sum())
                    which = np.repeat(np.arange(a_cells.size), per)
                    local = np.arange(total) - np.repeat(np.cumsum(per) - per, per)
                    a = order[start[a_cells][which] + local // cb[which]]
                    b = order[start[b_cells][which] + local % cb[which]]
                    diff = self.centers[b] - self.centers[a]
                    hit = np.einsum("ij,ij->i", diff, diff) < (self.radii[a] + self.radii[b]) ** 2
                    # within one cell keep a < b; across cells every pair is new
                    hit &= (a < b) if (dx, dy, dz) == (0, 0, 0) else True
                    firsts.append(a[hit])
                    seconds.append(b[hit])
        half_i = np.concatenate(firsts)
        half_j = np.concatenate(seconds)
        i = np.concatenate((half_i, half_j))
        j = np.concatenate((half_j, half_i))
        sort = np.argsort(i * n + j)
        return i[sort], j[sort]

    # ------------------------------------------------------------- ray walk
    def ray_cells(
        self, origin: np.ndarray, direction: np.ndarray, t_min: float = 0.0, t_max: float = np.inf
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Exact 3D-DDA (Amanatides & Woo 1987) of the ray o + t d, t in [t_min, t_max].

        Returns (cells (M, 3) int64, t_enter (M,), t_exit (M,)) in visiting order, with
        t_enter[i+1] == t_exit[i]. Next-boundary distances are recomputed from the cell
        index each step rather than accumulated, so no error builds up along long rays.
        This is the CPU reference for the GPU traversal.
        """
        o = np.asarray(origin, dtype=np.float64).reshape(3)
        d = np.asarray(direction, dtype=np.float64).reshape(3)
        empty = (np.empty((0, 3), dtype=np.int64), np.empty(0), np.empty(0))
        if not (np.all(np.isfinite(o)) and np.all(np.isfinite(d))) or not np.any(d):
            return empty
        lo, hi = self.origin, self.upper
        t0, t1 = float(t_min), float(t_max)
        for axis in range(3):
            if d[axis] == 0.0:
                if not (lo[axis] <= o[axis] < hi[axis]):
                    return empty
                continue
            ta = (lo[axis] - o[axis]) / d[axis]
            tb = (hi[axis] - o[axis]) / d[axis]
            t0 = max(t0, min(ta, tb))
            t1 = min(t1, max(ta, tb))
        if not t0 < t1:
            return empty
        cell = self.cell_index(o + t0 * d)
        step = np.where(d > 0, 1, -1).astype(np.int64)
        cells: list[np.ndarray] = []
        enters: list[float] = []
        exits: list[float] = []
        t = t0
        with np.errstate(divide="ignore"):
            inv = np.where(d != 0.0, 1.0 / np.where(d != 0.0, d, 1.0), np.inf)
        while True:
            boundary = self.origin + (cell + (step > 0)) * self.cell_size
            t_next = np.where(d != 0.0, (boundary - o) * inv, np.inf)
            axis = int(np.argmin(t_next))
            t_exit = min(float(t_next[axis]), t1)
            cells.append(cell.copy())
            enters.append(t)
            exits.append(t_exit)
            if t_exit >= t1:
                break
            cell[axis] += step[axis]
            if cell[axis] < 0 or cell[axis] >= self.dims[axis]:
                break
            t = t_exit
        return np.array(cells, dtype=np.int64), np.array(enters), np.array(exits)

    # ------------------------------------------------------------ reporting
    @property
    def nbytes(self) -> int:
        return int(self.cell_start.nbytes + self.cell_atoms.nbytes)

    def stats(self) -> GridStats:
        counts = np.diff(self.cell_start.astype(np.int64))
        nonempty = counts[counts > 0]
        return GridStats(
            cell_size=self.cell_size,
            dims=tuple(int(v) for v in self.dims),  # type: ignore[arg-type]
            n_cells=self.n_cells,
            n_nonempty=int(nonempty.size),
            max_per_cell=int(nonempty.max()) if nonempty.size else 0,
            mean_per_nonempty=float(nonempty.mean()) if nonempty.size else 0.0,
            bytes=self.nbytes,
        )


def default_cell_size(radii: np.ndarray) -> float:
    """The largest sphere diameter: each sphere then overlaps at most 8 cells."""
    return float(2.0 * np.max(radii))
