"""God-object proxy on the union of expanded spheres (the SAS as the probe centre sees it).

The free space is F = {x : |x - c_i| >= R_i for every atom i}, R_i = vdW radius + probe
radius. The proxy p stays in F; each tick it moves toward the goal g (the device tip
mapped into the molecule) and stops at a constrained local minimum of |p - g|, the
god-object of Zilles & Salisbury with the implicit spheres of Stocks & Laycock (2008)
as constraints. One tick iterates:

1. Active set. The spheres touching p (|p - c| = R) give outward normals n_k. The
   linearised problem  min |delta - d|, d = g - p, subject to n_k . delta >= 0  is a
   tiny QP (at most 3 of them are independent); enumerating the subsets of touching
   spheres finds its KKT point: delta = d + sum(lambda_k n_k), lambda_k > 0 for the
   spheres that hold the proxy back (the active set S), n_k . delta >= 0 for the
   others (released: the goal is on their outside). delta = 0 means p is a KKT point
   of the real problem: converged.
2. Path on the manifold of S, toward its own nearest point to g:
   - S empty: the straight segment to g;
   - one sphere: the great-circle arc toward the radial projection of g (or toward
     the tangent point seen from g when g is outside that sphere, where the proxy
     leaves the sphere on the next iteration);
   - two spheres: the arc of their intersection circle toward the point nearest g;
   - three spheres: the point where they meet; no motion.
   Distance to g falls monotonically along every one of these paths, so the
   iteration cannot cycle through real moves. A path is cut to MAX_STEP_A (chord),
   so it always fits a small neighbour query; only a free flight longer than
   LONG_FLIGHT_A (a device glitch, a jump) walks the grid cells along the segment
   instead (3D-DDA), so the proxy never lags behind a free goal.
3. First contact along the path with any other sphere, solved analytically (ray /
   sphere, and arc / sphere: |x(theta) - c|^2 - R^2 = K0 + A cos(theta) + B sin(theta)),
   using the spheres that the neighbour cache says can meet the path's bounding ball.
   The proxy stops there and that sphere joins the touching set.

Because the proxy only ever moves along paths checked against every sphere they can
meet, it never enters the SAS interior and never jumps across a thin part: pushing
the goal through an atom leaves the proxy on the near side (no pop-through).

Tolerances are far below the 1e-9 Å the tests allow: contact points are computed to
~1e-14 Å and re-projected onto their manifold at every move.

This module is the solver (steps 1 to 3 per iteration, the first contact along a path);
proxy_paths.py holds the geometry of steps 1 and 2 (the KKT point, the path on the
manifold of the active spheres).
"""

from __future__ import annotations

import math

import numpy as np
from sasprobe.daemon.haptics.neighbours import NeighbourCache, Sphere, deepest
from sasprobe.daemon.haptics.proxy_paths import (
    ANGLE_TOL,
    LONG_FLIGHT_A,
    kkt_step,
    manifold_path,
    snap_to_sphere,
)

TOUCH_A = 1e-10  # |distance to a sphere's surface| below this: touching
MOVE_EPS_A = 1e-11  # a KKT residual below this is converged
MAX_ITERATIONS = 32  # per tick; the proxy stays valid (just not yet converged) beyond it
REENTRY_MIN_RAD = 1e-6  # roots closer than this to the start of a leaving arc are round-off
TWO_PI = 2.0 * math.pi


class ProxySolver:
    """The proxy state (position, touching spheres) and its per-tick update.

    `position` is None while the proxy is unseated (no valid position yet, e.g. at
    start or after a reset while the goal is inside the SAS); `seat_if_free` seats it
    at the goal the first time the goal is in free space.
    """

    def __init__(self, cache: NeighbourCache):
        self.cache = cache
        self.position: tuple[float, float, float] | None = None
        self.touching: list[Sphere] = []  # active set after the last solve, largest push first
        self.multipliers: list[float] = []
        self.iterations = 0

    @property
    def seated(self) -> bool:
        return self.position is not None

    def unseat(self) -> None:
        self.position = None
        self.touching = []
        self.multipliers = []

    def is_free(self, x: float, y: float, z: float) -> bool:
        return deepest(self.cache, x, y, z) is None

    def seat_if_free(self, g: tuple[float, float, float]) -> bool:
        if self.position is None and self.is_free(*g):
            self.position = (float(g[0]), float(g[1]), float(g[2]))
            self.touching = []
            self.multipliers = []
        return self.position is not None

    # ------------------------------------------------------------------ solve
    def solve(
        self, g: tuple[float, float, float], budget_A: float = math.inf
    ) -> tuple[float, float, float]:
        """Move the (seated) proxy toward goal g; returns the new position.

        `budget_A` caps how far the proxy travels this tick (path length). Deep inside
        a non-convex region the local minimum the proxy sits in can vanish and the
        next one be Å away; a cap well above the goal's own motion spreads that snap
        over several ticks instead of one force step. The proxy stays valid either way.
        """
        px, py, pz = self.position  # type: ignore[misc]
        gx, gy, gz = g
        touching = self.touching
        iterations = 0
        budget = budget_A
        forced: tuple[int, ...] = ()
        while True:
            active, lams, (ex, ey, ez) = kkt_step(
                px, py, pz, touching, gx - px, gy - py, gz - pz, forced
            )
            touching = active
            if (
                iterations >= MAX_ITERATIONS
                or ex * ex + ey * ey + ez * ez <= MOVE_EPS_A * MOVE_EPS_A
            ):
                break
            path = manifold_path(px, py, pz, active, gx, gy, gz)
            if path is None:
                break
            iterations += 1
            exclude = tuple(s[0] for s in active)
            if path[0] == "seg":
                _, _, _, _, qx, qy, qz = path
                length = math.sqrt((qx - px) ** 2 + (qy - py) ** 2 + (qz - pz) ** 2)
                if length > budget:
                    if budget <= MOVE_EPS_A:
                        break  # spent for this tick
                    k = budget / length
                    path = (
                        "seg",
                        px,
                        py,
                        pz,
                        px + k * (qx - px),
                        py + k * (qy - py),
                        pz + k * (qz - pz),
                    )
                x0, y0, z0 = px, py, pz
                hit, (px, py, pz) = self._segment(path, exclude)
                moved = math.sqrt((px - x0) ** 2 + (py - y0) ** 2 + (pz - z0) ** 2)
            else:
                rho, theta = path[4], path[7]
                if rho * theta > budget:
                    if budget <= MOVE_EPS_A:
                        break  # spent for this tick
                    path = path[:7] + (budget / rho,)
                hit, (px, py, pz), angle = self._arc(path, exclude)
                moved = rho * angle
            budget -= moved
            if hit is not None:
                touching = active + [hit]
                if moved == 0.0 and hit[0] not in forced:
                    forced += (hit[0],)  # blocked at the start: hold it (see kkt_step)
        self.position = (px, py, pz)
        self.touching = touching
        self.multipliers = lams
        self.iterations = iterations
        return self.position

    # ---------------------------------------------------------- path / contact
    def _segment(self, path, exclude) -> tuple[Sphere | None, tuple[float, float, float]]:
        _, px, py, pz, qx, qy, qz = path
        dx, dy, dz = qx - px, qy - py, qz - pz
        a = dx * dx + dy * dy + dz * dz
        length = math.sqrt(a)
        if length > LONG_FLIGHT_A:
            candidates = self._spheres_along(px, py, pz, dx, dy, dz)
        else:
            candidates = self.cache.candidates(
                (px + qx) * 0.5, (py + qy) * 0.5, (pz + qz) * 0.5, length * 0.5 + 1e-9
            )
        best_t, best = 1.0, None
        for s in candidates:
            if s[0] in exclude:
                continue
            wx, wy, wz = px - s[1], py - s[2], pz - s[3]
            R = s[4]
            ww = wx * wx + wy * wy + wz * wz
            b = dx * wx + dy * wy + dz * wz  # half the linear coefficient
            dist = math.sqrt(ww) - R
            if dist <= TOUCH_A:
                if dist < -TOUCH_A:
                    continue  # already inside: cannot happen with a valid proxy; do not get stuck
                # Touching at the start: contact only when the segment heads inside. A line
                # that leaves (or grazes) a convex sphere never comes back into it.
                if b < -ANGLE_TOL * length * (R + dist):
                    best_t, best = 0.0, s
                    break
                continue
            c = ww - R * R
            disc = b * b - a * c
            if disc <= 0.0:
                continue
            t = (-b - math.sqrt(disc)) / a
            if 0.0 <= t < best_t:
                best_t, best = t, s
        if best is None:
            return None, (qx, qy, qz)
        x, y, z = px + best_t * dx, py + best_t * dy, pz + best_t * dz
        return best, snap_to_sphere(best, x, y, z)

    def _spheres_along(self, px, py, pz, dx, dy, dz) -> list[Sphere]:
        """Every sphere stored in a grid cell that the segment p -> p + d crosses."""
        grid = self.cache.grid
        cells, _, _ = grid.ray_cells(np.array((px, py, pz)), np.array((dx, dy, dz)), 0.0, 1.0)
        if cells.shape[0] == 0:
            return []
        ids = np.unique(np.concatenate([grid.atoms_in_cell(int(c)) for c in grid.flat_id(cells)]))
        centers = grid.centers[ids].tolist()
        radii = grid.radii[ids].tolist()
        return [(i, c[0], c[1], c[2], r) for i, c, r in zip(ids.tolist(), centers, radii)]

    def _arc(self, path, exclude) -> tuple[Sphere | None, tuple[float, float, float], float]:
        _, ox, oy, oz, rho, e1, e2, theta_end = path
        e1x, e1y, e1z = e1
        e2x, e2y, e2z = e2
        # Bounding ball of an arc of at most pi: the chord's midpoint, half the chord.
        c_end, s_end = math.cos(theta_end), math.sin(theta_end)
        mx = ox + rho * 0.5 * ((1.0 + c_end) * e1x + s_end * e2x)
        my = oy + rho * 0.5 * ((1.0 + c_end) * e1y + s_end * e2y)
        mz = oz + rho * 0.5 * ((1.0 + c_end) * e1z + s_end * e2z)
        half_chord = rho * math.sin(theta_end * 0.5)
        best_t, best = theta_end, None
        for s in self.cache.candidates(mx, my, mz, half_chord + 1e-9):
            if s[0] in exclude:
                continue
            wx, wy, wz = ox - s[1], oy - s[2], oz - s[3]
            R = s[4]
            k0 = wx * wx + wy * wy + wz * wz + rho * rho - R * R
            A = 2.0 * rho * (e1x * wx + e1y * wy + e1z * wz)
            B = 2.0 * rho * (e2x * wx + e2y * wy + e2z * wz)
            f0 = k0 + A  # |x(0) - c|^2 - R^2
            dist0 = math.sqrt(max(f0 + R * R, 0.0)) - R
            touching = dist0 <= TOUCH_A
            if touching:
                if dist0 < -TOUCH_A:
                    continue  # already inside: cannot happen with a valid proxy
                tol = ANGLE_TOL * 2.0 * rho * (R + dist0)
                # f'(0) = B: heading inside; f''(0) = -A: grazing but curving inside.
                if B < -tol or (B <= tol and A > 0.0):
                    best_t, best = 0.0, s
                    break
            m = math.hypot(A, B)
            if m == 0.0:
                continue
            q = -k0 / m
            if q <= -1.0 or q >= 1.0:
                continue  # f never changes sign along the circle
            # f = k0 + m cos(theta - phi): it decreases through zero at phi + acos(q).
            theta_in = (math.atan2(B, A) + math.acos(q)) % TWO_PI
            if touching and A <= 0.0 and theta_in < REENTRY_MIN_RAD:
                continue  # the leaving root, shifted by round-off
            if theta_in < best_t:
                best_t, best = theta_in, s
        c, sn = math.cos(best_t), math.sin(best_t)
        x = ox + rho * (c * e1x + sn * e2x)
        y = oy + rho * (c * e1y + sn * e2y)
        z = oz + rho * (c * e1z + sn * e2z)
        return best, (x, y, z), best_t
