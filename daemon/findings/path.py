"""The explored path: the probe's track decimated to points about a fixed distance apart,
without losing a contact.

A tick is kept when the probe has moved SPACING_A since the last kept one, and always
where a contact starts or ends, where the touched atom changes and where a mark was
dropped, so every contact and every mark is on the path. Each point carries the largest
force of the ticks it stands for (a push in one place is a force peak, not a distance).
Very long sessions widen the spacing so the path stays under MAX_POINTS.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from sasprobe.daemon.findings.session import Track

SPACING_A = 0.25
MAX_POINTS = 4000  # path points (the PDB export numbers them; the passage analysis costs ms each)


@dataclass
class ExploredPath:
    ticks: np.ndarray  # (M,) indices into the track of the kept ticks
    position_A: np.ndarray  # (M, 3)
    t_s: np.ndarray  # (M,)
    contact: np.ndarray  # (M,) bool
    force_max_N: np.ndarray  # (M,) largest |force| over the ticks since the previous point
    length_A: np.ndarray  # (M,) distance travelled along the path up to the point
    direction: np.ndarray  # (M, 3) unit direction of travel
    spacing_A: float

    @property
    def n_points(self) -> int:
        return int(self.ticks.size)


def explored_path(track: Track, spacing_A: float = SPACING_A) -> ExploredPath:
    p = track.proxy_A
    n = track.n_ticks
    steps = np.linalg.norm(np.diff(p, axis=0), axis=1)
    spacing = max(spacing_A, float(steps.sum()) / MAX_POINTS * 1.25)
    forced = np.zeros(n, dtype=bool)
    forced[[0, n - 1]] = True
    change = np.flatnonzero(track.contact[1:] != track.contact[:-1]) + 1
    forced[change] = forced[change - 1] = True  # the last tick of a run and the first of the next
    touched = np.flatnonzero((track.touched_atom[1:] != track.touched_atom[:-1]) & track.contact[1:]) + 1
    forced[touched] = True
    for mark in track.marks:
        forced[min(int(np.searchsorted(track.seq, mark["seq"])), n - 1)] = True
    kept = []
    points = p.tolist()
    last = points[0]
    for i, (point, must) in enumerate(zip(points, forced.tolist())):  # plain floats: one pass, cheap
        if must or math.dist(point, last) >= spacing:
            kept.append(i)
            last = point
    ticks = np.array(kept, dtype=np.int64)
    force = np.maximum.reduceat(track.force_N, np.concatenate(([0], ticks[:-1] + 1)))
    pos = p[ticks]
    length = np.concatenate(([0.0], np.cumsum(np.linalg.norm(np.diff(pos, axis=0), axis=1))))
    return ExploredPath(ticks=ticks, position_A=pos, t_s=track.t_s[ticks], contact=track.contact[ticks],
                force_max_N=force, length_A=length, direction=travel_directions(pos), spacing_A=spacing)


def travel_directions(points: np.ndarray, window: int = 2) -> np.ndarray:
    """Unit direction of travel at each point: the chord from `window` points back to
    `window` points ahead (about ±0.5 Å), so the plane across the path does not swing with
    every wobble of the hand; where the probe stood still (no chord), the nearest point's
    that has one; +z for a path that never moved."""
    m = len(points)
    if m < 2:
        return np.tile([0.0, 0.0, 1.0], (m, 1))
    k = np.arange(m)
    chord = points[np.minimum(k + window, m - 1)] - points[np.maximum(k - window, 0)]
    norm = np.linalg.norm(chord, axis=1)
    good = np.flatnonzero(norm > 1e-9)
    if good.size == 0:
        return np.tile([0.0, 0.0, 1.0], (m, 1))
    after = good[np.clip(np.searchsorted(good, k), 0, good.size - 1)]
    before = good[np.clip(np.searchsorted(good, k) - 1, 0, good.size - 1)]
    pick = np.where(np.abs(before - k) < np.abs(after - k), before, after)
    return chord[pick] / norm[pick][:, None]
