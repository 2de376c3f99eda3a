"""How much room the probe has: distances to the van der Waals surface through the uniform grid.

Two measures, both in Å, both from the vdW spheres (not the expanded ones the haptics feel):

- **clearance** at a point p: the distance from p to the nearest vdW surface,
  min_i |p − c_i| − r_i (negative inside an atom) — the largest probe radius that fits
  centred at p. For a probe in contact it equals the probe radius (that is what touching
  the SAS means), so along a recorded path it tells free from touching, not how narrow a
  place is.
- **passage radius** at p for a direction of travel t: the largest sphere whose centre
  lies in the plane through p perpendicular to t, found by climbing the clearance in that
  plane from p to its local maximum. In a channel this is the channel's radius there,
  whichever wall the probe slid along (CAVER's tunnel profile, for a path drawn by hand);
  on the open surface the climb leaves the molecule and the passage counts as open at
  OPEN_RADIUS_A.

The climb maximises f(q) = min_i d_i(q) over the plane, where each d_i = |q − c_i| − r_i is
convex: its tangent plane lies below it, so the linearised problem over a box of half
width Δ (a 3-variable LP, solved exactly by enumerating its vertices) is a lower bound of
f after the step. Every accepted step therefore raises f, with no line search; atoms too
far to matter within the box are left out of the LP (the box shrinks so that stays true).
Where the linearisation is flat (two walls facing each other, an atom straight ahead) a
step of second order is tried before stopping, so the result is a local maximum, not a
stalled ridge point.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import lru_cache
from itertools import combinations

import numpy as np
from sasprobe.molecule.grid import UniformGrid

OPEN_RADIUS_A = 5.0  # a passage wider than this is open surface for any solvent probe
# A passage counts only where it bounds a path over this much travel: a channel or pocket the
# probe went through, not one plane that happened to cut a small closed section out of an
# open surface (a tilt of a few degrees opens such a section again).
MIN_RUN_A = 0.5
BOTTLENECK_TOLERANCE_A = 0.05  # atoms this close to the widest sphere's surface line the passage
_MAX_LP_ATOMS = 16  # nearest atoms in one linearised step (the box shrinks to keep the rest out)
_STEP_A = (0.02, 1.0)  # smallest and largest box half width Δ of a climbing step
_MAX_ITERATIONS = 200
_GAIN_TOL_A = 1e-12
_ACTIVE_TOL_A = 1e-8  # atoms this close to the nearest count as touching the sphere
_SQRT2 = math.sqrt(2.0)


@dataclass(frozen=True)
class Passage:
    radius_A: float  # the widest sphere's radius (OPEN_RADIUS_A when open)
    center_A: np.ndarray  # its centre, in the plane through the point
    atoms: np.ndarray  # atoms within BOTTLENECK_TOLERANCE_A of its surface, nearest first
    open: bool  # the climb left the molecule: no passage bounds the path here


def persistent(
    bounded: np.ndarray, length_A: np.ndarray, min_run_A: float = MIN_RUN_A
) -> np.ndarray:
    """`bounded` (a flag per path point) without its runs that span less than min_run_A of
    path length (`length_A`: distance travelled up to each point)."""
    out = np.array(bounded, dtype=bool)
    edges = np.diff(np.concatenate(([0], out.astype(np.int8), [0])))
    for first, end in zip(np.flatnonzero(edges == 1), np.flatnonzero(edges == -1)):
        if length_A[end - 1] - length_A[first] < min_run_A:
            out[first:end] = False
    return out


def plane_basis(direction) -> tuple[np.ndarray, np.ndarray]:
    """Two orthonormal vectors spanning the plane perpendicular to a (non-zero) direction."""
    t = np.asarray(direction, dtype=np.float64)
    t = t / np.linalg.norm(t)
    helper = np.eye(3)[int(np.argmin(np.abs(t)))]
    a = np.cross(t, helper)
    a /= np.linalg.norm(a)
    return a, np.cross(t, a)


class ClearanceField:
    """The vdW spheres of a structure in their own uniform grid, queried for clearance."""

    def __init__(self, positions: np.ndarray, vdw_radii: np.ndarray):
        self.grid = UniformGrid(positions, vdw_radii)
        self.centers = self.grid.centers
        self.radii = self.grid.radii
        lo, hi = self.grid.origin, self.grid.upper
        self._box = (lo, hi, float(np.linalg.norm(hi - lo)))

    @classmethod
    def of(cls, structure) -> ClearanceField:
        return cls(structure.positions, structure.vdw_radii)

    # ------------------------------------------------------------------ clearance
    def near(self, point, extra: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
        """Atoms whose surface is within `extra` of the nearest one's, and their surface
        distances from the point, nearest first (the first is the clearance)."""
        p = np.asarray(point, dtype=np.float64).reshape(3)
        lo, hi, diagonal = self._box
        outside = float(np.linalg.norm(p - np.clip(p, lo, hi)))
        reach = max(self.grid.cell_size, extra) + outside
        while True:
            atoms = self.grid.spheres_within(p, reach)
            if atoms.size:
                diff = self.centers[atoms] - p
                d = np.sqrt(np.einsum("ij,ij->i", diff, diff)) - self.radii[atoms]
                nearest = float(d.min())
                # Every atom with d <= reach came back: these are all within `extra` of the nearest.
                if nearest + extra <= reach:
                    keep = d <= nearest + extra
                    order = np.argsort(d[keep], kind="stable")
                    return atoms[keep][order], d[keep][order]
                reach = nearest + extra
            else:
                reach = 2.0 * reach if reach < outside + diagonal else reach + diagonal

    def clearance(self, points) -> tuple[np.ndarray, np.ndarray]:
        """(distance to the nearest vdW surface, that atom) for each of (M, 3) points."""
        pts = np.asarray(points, dtype=np.float64).reshape(-1, 3)
        dist = np.empty(len(pts))
        atom = np.empty(len(pts), dtype=np.int64)
        for k, p in enumerate(pts):
            atoms, d = self.near(p)
            dist[k], atom[k] = d[0], atoms[0]
        return dist, atom

    # ------------------------------------------------------------------ passage
    def passage(self, point, direction, open_radius: float = OPEN_RADIUS_A) -> Passage:
        """The widest sphere centred in the plane through `point` perpendicular to `direction`
        that the climb from `point` reaches (see the module docstring)."""
        p = np.asarray(point, dtype=np.float64).reshape(3)
        basis = np.stack(plane_basis(direction))  # (2, 3)
        q = p.copy()
        step = _STEP_A[1] / 4
        for _ in range(_MAX_ITERATIONS):
            atoms, d = self.near(q, extra=2 * _SQRT2 * step)
            f = float(d[0])
            if f >= open_radius:
                return self._result(q, open_radius, True)
            box = step
            keep = max(_MAX_LP_ATOMS, int(np.count_nonzero(d <= f + _ACTIVE_TOL_A)))
            if atoms.size > keep:  # the atoms left out must stay out of reach of the step
                box = min(box, (float(d[keep]) - f) / (2 * _SQRT2))
                atoms, d = atoms[:keep], d[:keep]
            g = self._gradients(q, atoms, basis)
            delta, gain = _linearised_step(d, g, box) if box > 0 else (np.zeros(2), 0.0)
            if gain > _GAIN_TOL_A:
                q = q + delta @ basis
                if np.max(np.abs(delta)) >= 0.99 * box:
                    step = min(2 * step, _STEP_A[1])
                continue
            moved = self._second_order_step(q, f, d, g, basis, max(box, _STEP_A[0]))
            if moved is None:
                break
            q = moved
            step = max(step / 2, _STEP_A[0])
        atoms, d = self.near(q)
        return self._result(q, float(d[0]), False)

    def _gradients(self, q: np.ndarray, atoms: np.ndarray, basis: np.ndarray) -> np.ndarray:
        """In-plane gradients of the atoms' surface distances at q (unit vectors, projected)."""
        diff = q - self.centers[atoms]
        norm = np.linalg.norm(diff, axis=1)
        unit = diff / np.where(norm > 0, norm, 1.0)[:, None]
        return unit @ basis.T

    def _second_order_step(self, q, f, d, g, basis, box) -> np.ndarray | None:
        """Where no linearised step gains: a nearby point of higher clearance, or None at a
        strict local maximum. f can still rise, to second order, only along a direction no
        touching atom's gradient opposes (along the ridge of two facing walls, or anywhere
        an atom lies straight ahead of the plane); those are tried at shrinking steps."""
        active = g[d <= f + _ACTIVE_TOL_A]
        norms = np.linalg.norm(active, axis=1)
        turns = [np.stack([-a[1], a[0]]) / n for a, n in zip(active, norms) if n > 1e-9]
        if np.any(norms <= 1e-9):
            angles = np.linspace(0.0, 2 * np.pi, 8, endpoint=False)
            turns += list(np.stack([np.cos(angles), np.sin(angles)], axis=1))
        flat = [
            sign * u for u in turns for sign in (1.0, -1.0) if np.min(active @ (sign * u)) >= -1e-9
        ]
        if not flat:
            return None
        directions = np.array(flat) @ basis
        s = box
        while s >= 1e-7:
            for u in directions:
                trial = q + s * u
                if float(self.near(trial)[1][0]) > f + _GAIN_TOL_A:
                    return trial
            s /= 4
        return None

    def _result(self, q: np.ndarray, radius: float, is_open: bool) -> Passage:
        atoms, _ = self.near(q, extra=BOTTLENECK_TOLERANCE_A)
        return Passage(radius_A=radius, center_A=q, atoms=atoms, open=is_open)


def _linearised_step(d: np.ndarray, g: np.ndarray, box: float) -> tuple[np.ndarray, float]:
    """Maximise t(δ) = min_j (d_j + g_j·δ) over |δ|∞ ≤ box; returns (δ, t − min d).

    t is concave and piecewise linear, so its maximum over the box lies at a box corner,
    where two of its planes meet on a box edge, or where three meet inside: every such
    point is a candidate, and the best candidate's own t is the answer."""
    candidates = [np.array([[sx, sy] for sx in (-box, box) for sy in (-box, box)])]
    m = len(d)
    if m >= 2:
        i, j = _index_tuples(m, 2)
        for axis in (0, 1):
            other = 1 - axis
            for fixed in (-box, box):
                slope = g[j, other] - g[i, other]
                ok = np.abs(slope) > 1e-15
                free = ((d[i] - d[j]) + (g[i, axis] - g[j, axis]) * fixed)[ok] / slope[ok]
                free = free[np.abs(free) <= box]
                pts = np.empty((free.size, 2))
                pts[:, axis], pts[:, other] = fixed, free
                candidates.append(pts)
    if m >= 3:
        i, j, k = _index_tuples(m, 3)
        a11, a12 = g[i, 0] - g[j, 0], g[i, 1] - g[j, 1]  # (g_i − g_j)·δ = d_j − d_i, and so for k
        a21, a22 = g[i, 0] - g[k, 0], g[i, 1] - g[k, 1]
        b1, b2 = d[j] - d[i], d[k] - d[i]
        det = a11 * a22 - a12 * a21
        ok = np.abs(det) > 1e-15
        x = (b1[ok] * a22[ok] - a12[ok] * b2[ok]) / det[ok]  # Cramer's rule
        y = (a11[ok] * b2[ok] - b1[ok] * a21[ok]) / det[ok]
        inside = (np.abs(x) <= box) & (np.abs(y) <= box)
        candidates.append(np.stack([x[inside], y[inside]], axis=1))
    pts = np.concatenate(candidates)
    pts = np.vstack([np.zeros((1, 2)), pts])  # staying put is a candidate (gain 0)
    t = (d[None, :] + pts @ g.T).min(axis=1)
    best = int(np.argmax(t))
    return pts[best], float(t[best] - d.min())


@lru_cache(maxsize=64)
def _index_tuples(m: int, r: int) -> np.ndarray:
    """(r, C(m, r)) index arrays of all r-subsets of range(m)."""
    return np.array(list(combinations(range(m), r)), dtype=np.int64).reshape(-1, r).T
