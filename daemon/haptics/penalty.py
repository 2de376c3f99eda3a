"""The textbook penalty baseline, kept selectable so comparisons with the proxy are honest.

The goal itself is the probe: when it is inside one or more expanded spheres, the
force pushes it out along the normal of the sphere it is deepest inside, in
proportion to that penetration (a spring to the surface point c + R n). It has no
memory, so past the middle of a thin part the deepest sphere's normal flips and the
user is pushed out through the far side (pop-through), and at a crease between two
spheres the normal jumps from one sphere to the other (force discontinuity). Both are
measured in `sasprobe bench haptics`.
"""

from __future__ import annotations

from sasprobe.daemon.haptics.neighbours import NeighbourCache, Sphere, deepest


def penalty_contact(
    cache: NeighbourCache, gx: float, gy: float, gz: float
) -> tuple[tuple[float, float, float], Sphere] | None:
    """(surface point of the deepest sphere containing g, that sphere), or None when g is free."""
    hit = deepest(cache, gx, gy, gz)
    if hit is None:
        return None
    best, _, best_dist = hit
    _, cx, cy, cz, R = best
    if best_dist == 0.0:
        return (cx, cy, cz + R), best  # at the very centre the normal is undefined: pick +z
    k = R / best_dist
    return (cx + (gx - cx) * k, cy + (gy - cy) * k, cz + (gz - cz) * k), best
