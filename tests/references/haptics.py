"""Independent references for the haptics tests (numpy, no code shared with sasprobe.daemon).

- `constrained_candidates`: every point where the distance to a goal can be stationary
  on the boundary of a union of spheres: the nearest and farthest point of each sphere,
  of each pairwise intersection circle, and every triple intersection point, kept when
  outside all spheres. The global nearest free point is always among them.
- `is_local_min`: dense random sampling of free points around a point.
- `synthetic_structure`: a Structure from coordinates via a real PDB text and the
  real parser (carbon atoms unless told otherwise).
"""

from __future__ import annotations

from itertools import combinations

import numpy as np
from sasprobe.molecule import parse_structure


def signed_distance(points: np.ndarray, centers: np.ndarray, radii: np.ndarray) -> np.ndarray:
    """Distance of each point to the union's surface, negative inside (min over spheres)."""
    points = np.atleast_2d(points)
    d = np.linalg.norm(points[:, None, :] - centers[None, :, :], axis=2) - radii[None, :]
    return d.min(axis=1)


def _sphere_points(c, r, g):
    u = g - c
    n = np.linalg.norm(u)
    if n == 0:
        return []
    return [c + r * u / n, c - r * u / n]


def _circle_points(c1, r1, c2, r2, g):
    axis = c2 - c1
    d = np.linalg.norm(axis)
    if d == 0 or d >= r1 + r2 or d <= abs(r1 - r2):
        return []
    a = axis / d
    along = (d * d + r1 * r1 - r2 * r2) / (2 * d)
    rho = np.sqrt(r1 * r1 - along * along)
    m = c1 + along * a
    w = (g - m) - np.dot(g - m, a) * a
    n = np.linalg.norm(w)
    if n < 1e-12:
        return []
    return [m + rho * w / n, m - rho * w / n]


def _triple_points(c1, r1, c2, r2, c3, r3):
    d = np.linalg.norm(c2 - c1)
    if d == 0:
        return []
    ex = (c2 - c1) / d
    i = np.dot(ex, c3 - c1)
    ey = c3 - c1 - i * ex
    ny = np.linalg.norm(ey)
    if ny < 1e-12:
        return []
    ey /= ny
    ez = np.cross(ex, ey)
    j = np.dot(ey, c3 - c1)
    x = (r1 * r1 - r2 * r2 + d * d) / (2 * d)
    y = (r1 * r1 - r3 * r3 + i * i + j * j) / (2 * j) - i * x / j
    z2 = r1 * r1 - x * x - y * y
    if z2 < 0:
        return []
    z = np.sqrt(z2)
    base = c1 + x * ex + y * ey
    return [base + z * ez, base - z * ez]


def constrained_candidates(
    centers: np.ndarray, radii: np.ndarray, g: np.ndarray, tol: float = 1e-9
) -> np.ndarray:
    """Free stationary points of |x - g| on the union's boundary (plus g itself when free)."""
    pts = []
    n = len(centers)
    for i in range(n):
        pts += _sphere_points(centers[i], radii[i], g)
    for i, j in combinations(range(n), 2):
        pts += _circle_points(centers[i], radii[i], centers[j], radii[j], g)
    for i, j, k in combinations(range(n), 3):
        pts += _triple_points(centers[i], radii[i], centers[j], radii[j], centers[k], radii[k])
    pts.append(np.asarray(g, dtype=float))
    pts = np.array(pts)
    return pts[signed_distance(pts, centers, radii) >= -tol]


def nearest_free_point(centers, radii, g) -> np.ndarray:
    cands = constrained_candidates(centers, radii, g)
    return cands[np.argmin(np.linalg.norm(cands - g, axis=1))]


def is_local_min(p, g, centers, radii, rng, radius: float = 0.05, samples: int = 4000) -> bool:
    """No free point within `radius` of p is nearer to g (beyond 1e-9 Å)."""
    x = p + radius * rng.uniform(-1, 1, size=(samples, 3))
    free = x[signed_distance(x, centers, radii) >= 0]
    if free.size == 0:
        return True
    return bool(np.linalg.norm(free - g, axis=1).min() >= np.linalg.norm(p - g) - 1e-9)


def local_minima(centers, radii, g, rng) -> np.ndarray:
    cands = constrained_candidates(centers, radii, g)
    keep = [c for c in cands if is_local_min(c, g, centers, radii, rng)]
    # merge duplicates (a candidate can be produced by several spheres/circles)
    out: list[np.ndarray] = []
    for c in keep:
        if all(np.linalg.norm(c - o) > 1e-7 for o in out):
            out.append(c)
    return np.array(out)


def synthetic_structure(points, element: str = "C", name: str = "synthetic"):
    """A Structure of single atoms at `points` (Å), through a PDB text and the real parser."""
    lines = []
    for k, (x, y, z) in enumerate(np.asarray(points, dtype=float), start=1):
        lines.append(
            f"HETATM{k:5d}  {element:<3s} UNK A{k % 10000:4d}    {x:8.3f}{y:8.3f}{z:8.3f}"
            f"  1.00  0.00          {element:>2s}"
        )
    lines.append("END")
    return parse_structure("\n".join(lines).encode(), name=name, source=f"synthetic:{name}")
