"""The geometry of the god-object proxy's iteration (proxy.py): the KKT point of the
linearised step over the touching spheres, and the path toward the goal on the manifold
of the active ones (segment, great-circle arc, arc of two spheres' circle, or nothing at
three), cut to MAX_STEP_A. Plain float arithmetic, in order: deterministic."""

from __future__ import annotations

import math
from itertools import combinations

from sasprobe.daemon.haptics.neighbours import Sphere

ANGLE_TOL = 1e-9  # cosine tolerance for "entering" / "leaving" a sphere
MAX_STEP_A = 2.0  # longest path (chord) per iteration, keeps neighbour queries small
LONG_FLIGHT_A = 8.0  # free segments longer than this are checked along the grid's cells


def snap_to_sphere(s: Sphere, x: float, y: float, z: float) -> tuple[float, float, float]:
    """Project a point (a computed contact) exactly onto a sphere's surface."""
    dx, dy, dz = x - s[1], y - s[2], z - s[3]
    length = math.sqrt(dx * dx + dy * dy + dz * dz)
    if length == 0.0:
        return x, y, z
    k = s[4] / length
    return s[1] + dx * k, s[2] + dy * k, s[3] + dz * k


def unit_normal(s: Sphere, px: float, py: float, pz: float) -> tuple[float, float, float]:
    dx, dy, dz = px - s[1], py - s[2], pz - s[3]
    length = math.sqrt(dx * dx + dy * dy + dz * dz)
    if length == 0.0:
        return 0.0, 0.0, 1.0
    return dx / length, dy / length, dz / length


def kkt_step(px, py, pz, touching: list[Sphere], dx, dy, dz, forced: tuple[int, ...] = ()):
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
    normals = [unit_normal(s, px, py, pz) for s in touching]
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
        if (
            (l1 <= tol and a not in must)
            or (l2 <= tol and b not in must)
            or (l3 <= tol and c3 not in must)
        ):
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


def truncate_arc(theta: float, rho: float) -> float:
    """Largest angle <= theta whose chord on a circle of radius rho is <= MAX_STEP_A."""
    if 2.0 * rho <= MAX_STEP_A:
        return theta
    return min(theta, 2.0 * math.asin(MAX_STEP_A / (2.0 * rho)))


def manifold_path(px, py, pz, active: list[Sphere], gx, gy, gz):
    """The path toward the nearest point to g on the manifold of the active set."""
    if not active:
        dx, dy, dz = gx - px, gy - py, gz - pz
        length = math.sqrt(dx * dx + dy * dy + dz * dz)
        if MAX_STEP_A < length <= LONG_FLIGHT_A:
            k = MAX_STEP_A / length
            gx, gy, gz = px + dx * k, py + dy * k, pz + dz * k
        return ("seg", px, py, pz, gx, gy, gz)
    if len(active) == 1:
        return sphere_arc(px, py, pz, active[0], gx, gy, gz)
    if len(active) == 2:
        return circle_arc(px, py, pz, active[0], active[1], gx, gy, gz)
    return None  # three spheres pin the proxy


def sphere_arc(px, py, pz, s: Sphere, gx, gy, gz):
    _, cx, cy, cz, R = s
    nx, ny, nz = unit_normal(s, px, py, pz)
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
    theta = truncate_arc(phi0 - phi_end, R)
    if theta <= 0.0:
        return None
    return ("arc", cx, cy, cz, R, (nx, ny, nz), (tx / tlen, ty / tlen, tz / tlen), theta)


def circle_arc(px, py, pz, si: Sphere, sj: Sphere, gx, gy, gz):
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
    theta = truncate_arc(psi, rho)
    if theta <= 0.0:
        return None
    return ("arc", mx, my, mz, rho, e1, e2, theta)
