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
"""

from __future__ import annotations

import math
from itertools import combinations

import numpy as np

from sasprobe.daemon.haptics.neighbours import NeighbourCache, Sphere, deepest

TOUCH_A = 1e-10  # |distance to a sphere's surface| below this: touching
ANGLE_TOL = 1e-9  # cosine tolerance for "entering" / "leaving" a sphere
MOVE_EPS_A = 1e-11  # a KKT residual below this is converged
MAX_STEP_A = 2.0  # longest path (chord) per iteration, keeps neighbour queries small
LONG_FLIGHT_A = 8.0  # free segments longer than this are checked along the grid's cells
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
    def solve(self, g: tuple[float, float, float], budget_A: float = math.inf) -> tuple[float, float, float]:
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
            active, lams, (ex, ey, ez) = _kkt(px, py, pz, touching, gx - px, gy - py, gz - pz, forced)
            touching = active
            if iterations >= MAX_ITERATIONS or ex * ex + ey * ey + ez * ez <= MOVE_EPS_A * MOVE_EPS_A:
                break
            path = _path(px, py, pz, active, gx, gy, gz)
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
                    path = ("seg", px, py, pz, px + k * (qx - px), py + k * (qy - py), pz + k * (qz - pz))
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
                    forced += (hit[0],)  # blocked at the start: hold it (see _kkt)
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
            candidates = self.cache.candidates((px + qx) * 0.5, (py + qy) * 0.5, (pz + qz) * 0.5, length * 0.5 + 1e-9)
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
        return best, _snap(best, x, y, z)

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


# -------------------------------------------------------------- geometry helpers
def _snap(s: Sphere, x: float, y: float, z: float) -> tuple[float, float, float]:
    """Project a point (a computed contact) exactly onto a sphere's surface."""
    dx, dy, dz = x - s[1], y - s[2], z - s[3]
    length = math.sqrt(dx * dx + dy * dy + dz * dz)
    if length == 0.0:
        return x, y, z
    k = s[4] / length
    return s[1] + dx * k, s[2] + dy * k, s[3] + dz * k


def _unit_normal(s: Sphere, px: float, py: float, pz: float) -> tuple[float, float, float]:
    dx, dy, dz = px - s[1], py - s[2], pz - s[3]
    length = math.sqrt(dx * dx + dy * dy + dz * dz)
    if length == 0.0:
        return 0.0, 0.0, 1.0
    return dx / length, dy / length, dz / length


def _kkt(px, py, pz, touching: list[Sphere], dx, dy, dz, forced: tuple[int, ...] = ()):
    """KKT point of min |delta - d| s.t. n_k . delta >= 0 over the touching spheres.

    Returns (active spheres sorted by multiplier, multipliers, delta). The QP is
    strictly convex, so the first subset that satisfies the KKT conditions is the
    answer; subsets with (nearly) dependent normals are skipped. `forced` atoms are
    held as equalities whatever their multiplier: spheres that blocked a path at its
    very start although the linearisation released them (a circle tangent to a third
    sphere and curving into it), so the next path cannot run into them again.
    Written out per subset size: this runs several times per tick.
    """
    dlen = math.sqrt(dx * dx + dy * dy + dz * dz)
    if dlen == 0.0 or not touching:
        return [], [], (dx, dy, dz)
    tol = ANGLE_TOL * dlen
    normals = [_unit_normal(s, px, py, pz) for s in touching]
    nd = [n[0] * dx + n[1] * dy + n[2] * dz for n in normals]
    count = len(touching)
    must = tuple(k for k in range(count) if touching[k][0] in forced) if forced else ()

    def feasible(delta, skip) -> bool:
        ex, ey, ez = delta
        elen = math.sqrt(ex * ex + ey * ey + ez * ez)
        for k in range(count):
            if k not in skip:
                n = normals[k]
                if n[0] * ex + n[1] * ey + n[2] * ez < -ANGLE_TOL * elen:
                    return False
        return True

    if not must and all(v >= -tol for v in nd):
        return [], [], (dx, dy, dz)
    for a in range(count):
        if must and must != (a,):
            continue
        lam = -nd[a]
        if lam <= tol and a not in must:
            continue
        n = normals[a]
        delta = (dx + lam * n[0], dy + lam * n[1], dz + lam * n[2])
        if feasible(delta, (a,)):
            return [touching[a]], [lam], delta
    for a, b in combinations(range(count), 2):
        if must and not all(k in (a, b) for k in must):
            continue
        na, nb = normals[a], normals[b]
        c = na[0] * nb[0] + na[1] * nb[1] + na[2] * nb[2]
        det = 1.0 - c * c
        if det < 1e-12:
            continue
        la = (-nd[a] + c * nd[b]) / det
        lb = (-nd[b] + c * nd[a]) / det
        if (la <= tol and a not in must) or (lb <= tol and b not in must):
            continue
        delta = (
            dx + la * na[0] + lb * nb[0],
            dy + la * na[1] + lb * nb[1],
            dz + la * na[2] + lb * nb[2],
        )
        if feasible(delta, (a, b)):
            if la >= lb:
                return [touching[a], touching[b]], [la, lb], delta
            return [touching[b], touching[a]], [lb, la], delta
    for a, b, c3 in combinations(range(count), 3):
        if must and not all(k in (a, b, c3) for k in must):
            continue
        n1, n2, n3 = normals[a], normals[b], normals[c3]
        g12 = n1[0] * n2[0] + n1[1] * n2[1] + n1[2] * n2[2]
        g13 = n1[0] * n3[0] + n1[1] * n3[1] + n1[2] * n3[2]
        g23 = n2[0] * n3[0] + n2[1] * n3[1] + n2[2] * n3[2]
        det = 1.0 + 2.0 * g12 * g13 * g23 - g12 * g12 - g13 * g13 - g23 * g23
        if det < 1e-12:
            continue
        r1, r2, r3 = -nd[a], -nd[b], -nd[c3]
        # Adjugate of the symmetric Gram matrix [[1,g12,g13],[g12,1,g23],[g13,g23,1]].
        a12, a13, a23 = g13 * g23 - g12, g12 * g23 - g13, g12 * g13 - g23
        l1 = ((1.0 - g23 * g23) * r1 + a12 * r2 + a13 * r3) / det
        l2 = (a12 * r1 + (1.0 - g13 * g13) * r2 + a23 * r3) / det
        l3 = (a13 * r1 + a23 * r2 + (1.0 - g12 * g12) * r3) / det
        if (l1 <= tol and a not in must) or (l2 <= tol and b not in must) or (l3 <= tol and c3 not in must):
            continue
        delta = (
            dx + l1 * n1[0] + l2 * n2[0] + l3 * n3[0],
            dy + l1 * n1[1] + l2 * n2[1] + l3 * n3[1],
            dz + l1 * n1[2] + l2 * n2[2] + l3 * n3[2],
        )
        if feasible(delta, (a, b, c3)):
            ranked = sorted(zip((l1, l2, l3), (a, b, c3)), key=lambda item: -item[0])
            return [touching[i] for _, i in ranked], [lam for lam, _ in ranked], delta
    # Degenerate contact (e.g. four spheres through one point): stay put this tick.
    return touching[:3], [0.0] * min(count, 3), (0.0, 0.0, 0.0)


def _truncate(theta: float, rho: float) -> float:
    """Largest angle <= theta whose chord on a circle of radius rho is <= MAX_STEP_A."""
    if 2.0 * rho <= MAX_STEP_A:
        return theta
    return min(theta, 2.0 * math.asin(MAX_STEP_A / (2.0 * rho)))


def _path(px, py, pz, active: list[Sphere], gx, gy, gz):
    """The path toward the nearest point to g on the manifold of the active set."""
    if not active:
        dx, dy, dz = gx - px, gy - py, gz - pz
        length = math.sqrt(dx * dx + dy * dy + dz * dz)
        if MAX_STEP_A < length <= LONG_FLIGHT_A:
            k = MAX_STEP_A / length
            gx, gy, gz = px + dx * k, py + dy * k, pz + dz * k
        return ("seg", px, py, pz, gx, gy, gz)
    if len(active) == 1:
        return _sphere_arc(px, py, pz, active[0], gx, gy, gz)
    if len(active) == 2:
        return _circle_arc(px, py, pz, active[0], active[1], gx, gy, gz)
    return None  # three spheres pin the proxy


def _sphere_arc(px, py, pz, s: Sphere, gx, gy, gz):
    _, cx, cy, cz, R = s
    nx, ny, nz = _unit_normal(s, px, py, pz)
    ux, uy, uz = gx - cx, gy - cy, gz - cz
    glen = math.sqrt(ux * ux + uy * uy + uz * uz)
    if glen < 1e-12:
        return None  # goal at the centre: every surface point is equally near
    un = nx * ux + ny * uy + nz * uz
    tx, ty, tz = ux - un * nx, uy - un * ny, uz - un * nz
    tlen = math.sqrt(tx * tx + ty * ty + tz * tz)
    if tlen <= 1e-12 * glen:
        return None  # goal straight behind the centre: an unstable balance, stay
    phi0 = math.atan2(tlen, un)
    phi_end = math.acos(R / glen) if glen > R else 0.0  # tangent point seen from an outside goal
    theta = _truncate(phi0 - phi_end, R)
    if theta <= 0.0:
        return None
    return ("arc", cx, cy, cz, R, (nx, ny, nz), (tx / tlen, ty / tlen, tz / tlen), theta)


def _circle_arc(px, py, pz, si: Sphere, sj: Sphere, gx, gy, gz):
    _, xi, yi, zi, ri = si
    _, xj, yj, zj, rj = sj
    ax, ay, az = xj - xi, yj - yi, zj - zi
    dist = math.sqrt(ax * ax + ay * ay + az * az)
    if dist == 0.0:
        return None
    ax, ay, az = ax / dist, ay / dist, az / dist
    along = (dist * dist + ri * ri - rj * rj) / (2.0 * dist)
    rho2 = ri * ri - along * along
    if rho2 <= 1e-18:
        return None
    rho = math.sqrt(rho2)
    mx, my, mz = xi + along * ax, yi + along * ay, zi + along * az
    wx, wy, wz = px - mx, py - my, pz - mz
    wa = wx * ax + wy * ay + wz * az
    wx, wy, wz = wx - wa * ax, wy - wa * ay, wz - wa * az
    wlen = math.sqrt(wx * wx + wy * wy + wz * wz)
    if wlen == 0.0:
        return None
    e1 = (wx / wlen, wy / wlen, wz / wlen)
    # In-plane tangent at p: axis x e1.
    tx = ay * e1[2] - az * e1[1]
    ty = az * e1[0] - ax * e1[2]
    tz = ax * e1[1] - ay * e1[0]
    ux, uy, uz = gx - mx, gy - my, gz - mz
    ua = ux * ax + uy * ay + uz * az
    ux, uy, uz = ux - ua * ax, uy - ua * ay, uz - ua * az
    ulen = math.sqrt(ux * ux + uy * uy + uz * uz)
    if ulen <= 1e-12 * rho:
        return None  # goal on the circle's axis: every circle point is equally near
    psi = math.atan2(tx * ux + ty * uy + tz * uz, e1[0] * ux + e1[1] * uy + e1[2] * uz)
    if psi < 0.0:
        e2 = (-tx, -ty, -tz)
        psi = -psi
    else:
        e2 = (tx, ty, tz)
    theta = _truncate(psi, rho)
    if theta <= 0.0:
        return None
    return ("arc", mx, my, mz, rho, e1, e2, theta)
