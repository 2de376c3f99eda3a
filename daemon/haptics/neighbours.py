"""A local cache of the spheres around the probe, refilled from the uniform grid.

The haptic loop asks many small questions per tick ("which spheres can this path
touch?"). Each grid query costs tens of µs of numpy calls, so the cache asks the grid
once for every sphere whose surface lies within `reach` of a centre, keeps them as
plain-Python tuples, and answers from that list while the questions stay inside the
ball it covers. Correctness: a cache filled at centre c0 with reach Rc holds every
sphere with |c - c0| - R <= Rc, so any sphere meeting a ball (q, r) with
|q - c0| + r <= Rc is in it (triangle inequality); otherwise it refills at q.

Per-tick cost therefore depends on the local atom density, not on molecule size.
"""

from __future__ import annotations

import math

from sasprobe.molecule.grid import UniformGrid

DEFAULT_REACH_A = 2.0

# (atom index, centre x, y, z, radius) in Å
Sphere = tuple[int, float, float, float, float]


class NeighbourCache:
    def __init__(self, grid: UniformGrid, reach_A: float = DEFAULT_REACH_A):
        self.grid = grid
        self.reach = float(reach_A)
        self._center: tuple[float, float, float] | None = None
        self._radius = -1.0
        self._spheres: list[Sphere] = []
        self.refills = 0

    def clear(self) -> None:
        self._center = None
        self._spheres = []

    def candidates(self, qx: float, qy: float, qz: float, r: float) -> list[Sphere]:
        """Every sphere that meets the closed ball (q, r), from the cache (refilled if needed)."""
        c = self._center
        if (
            c is None
            or math.sqrt((qx - c[0]) ** 2 + (qy - c[1]) ** 2 + (qz - c[2]) ** 2) + r > self._radius
        ):
            self._refill(qx, qy, qz, r + self.reach)
        out = []
        for s in self._spheres:
            dx = s[1] - qx
            dy = s[2] - qy
            dz = s[3] - qz
            lim = s[4] + r
            if dx * dx + dy * dy + dz * dz <= lim * lim:
                out.append(s)
        return out

    def sphere(self, index: int) -> Sphere:
        c = self.grid.centers[index]
        return (int(index), float(c[0]), float(c[1]), float(c[2]), float(self.grid.radii[index]))

    def _refill(self, x: float, y: float, z: float, radius: float) -> None:
        # A hair of slack keeps the boundary case (a sphere exactly at the reach) inside.
        idx = self.grid.spheres_within((x, y, z), radius + 1e-9)
        centers = self.grid.centers[idx].tolist()
        radii = self.grid.radii[idx].tolist()
        self._spheres = [(i, c[0], c[1], c[2], r) for i, c, r in zip(idx.tolist(), centers, radii)]
        self._center = (x, y, z)
        self._radius = radius
        self.refills += 1


def deepest(
    cache: NeighbourCache, x: float, y: float, z: float
) -> tuple[Sphere, float, float] | None:
    """(sphere a point is deepest inside, depth Å, distance to its centre Å), or None when
    outside all."""
    best = None
    best_depth = 0.0
    best_dist = 0.0
    for s in cache.candidates(x, y, z, 0.0):
        dist = math.sqrt((x - s[1]) ** 2 + (y - s[2]) ** 2 + (z - s[3]) ** 2)
        depth = s[4] - dist
        if depth > best_depth:
            best, best_depth, best_dist = s, depth, dist
    return None if best is None else (best, best_depth, best_dist)
