"""The explored path: the probe's track decimated to points about a fixed distance apart,
without losing a contact.

A tick is kept when the probe has moved SPACING_A since the last kept one; where it
wedges between three atoms or more (its centre pinned where their SAS spheres meet: where
passages close around it), unless the last kept point is that same wedge within
PIN_SPACING_A; and always
where a mark was dropped and at both ends. Each point stands for the ticks since the one
before: it is in contact when any of them was and carries their largest force, so no
contact and no force peak is lost (a push in one place is a force peak, not a distance).
Very long sessions widen the spacings so the path stays under MAX_POINTS.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from sasprobe.daemon.findings.session import Track

SPACING_A = 0.25
PIN_SPACING_A = 0.05  # a probe rocking in a pocket re-enters the same wedge every few ticks
MAX_POINTS = 4000  # path points (the PDB export numbers them; the passage analysis costs ms each)


@dataclass
class ExploredPath:
    ticks: np.ndarray  # (M,) indices into the track of the kept ticks
    position_A: np.ndarray  # (M, 3)
    t_s: np.ndarray  # (M,)
    contact: np.ndarray  # (M,) bool: some tick since the previous point touched the surface
    force_max_N: np.ndarray  # (M,) largest |force| over the ticks since the previous point
    length_A: np.ndarray  # (M,) distance travelled along the path up to the point
    direction: np.ndarray  # (M, 3) unit direction of travel
    spacing_A: float

    @property
    def n_points(self) -> int:
        return int(self.ticks.size)


def explored_path(
    track: Track, touching: dict[int, list[int]], spacing_A: float = SPACING_A
) -> ExploredPath:
    """The path of a track; `touching` maps each contact tick to the atoms it touches."""
    p = track.proxy_A
    n = track.n_ticks
    touched = [frozenset(touching.get(i, ())) for i in range(n)]
    wedged = [
        len(now) >= 3 and now != before
        for now, before in zip(touched, [frozenset()] + touched[:-1])
    ]
    forced = np.zeros(n, dtype=bool)
    forced[[0, n - 1]] = True
    for mark in track.marks:
        forced[min(int(np.searchsorted(track.seq, mark["seq"])), n - 1)] = True
    travelled = float(np.linalg.norm(np.diff(p, axis=0), axis=1).sum())
    widen = max(1.0, travelled / (MAX_POINTS * spacing_A) * 1.25)
    while True:
        ticks = _kept_ticks(
            p.tolist(), forced.tolist(), wedged, touched, spacing_A * widen, PIN_SPACING_A * widen
        )
        if ticks.size <= MAX_POINTS or widen > 1e6:
            break
        widen *= 1.5
    # each point stands for ticks starts[k] .. ticks[k]
    starts = np.concatenate(([0], ticks[:-1] + 1))
    force = np.maximum.reduceat(track.force_N, starts)
    contact = np.logical_or.reduceat(track.contact, starts)
    pos = p[ticks]
    length = np.concatenate(([0.0], np.cumsum(np.linalg.norm(np.diff(pos, axis=0), axis=1))))
    return ExploredPath(
        ticks=ticks,
        position_A=pos,
        t_s=track.t_s[ticks],
        contact=contact,
        force_max_N=force,
        length_A=length,
        direction=travel_directions(pos),
        spacing_A=spacing_A * widen,
    )


def _kept_ticks(
    points: list, forced: list, wedged: list, touched: list, spacing: float, pin_spacing: float
) -> np.ndarray:
    """One pass in plain floats over the ticks: the indices the path keeps."""
    kept = []
    last, last_touched = points[0], None
    for i, (point, must, wedge) in enumerate(zip(points, forced, wedged)):
        moved = math.dist(point, last)
        if (
            must
            or moved >= spacing
            or (wedge and (touched[i] != last_touched or moved >= pin_spacing))
        ):
            kept.append(i)
            last, last_touched = point, touched[i]
    return np.array(kept, dtype=np.int64)


def travel_directions(points: np.ndarray, half_window_A: float = 0.5) -> np.ndarray:
    """Unit direction of travel at each point: the chord between the points half_window_A of
    path behind and ahead of it, so the plane across the path does not swing with every
    wobble of the hand; where that chord is empty (the probe stood still), the nearest
    point's that is not; +z for a path that never moved."""
    m = len(points)
    if m < 2:
        return np.tile([0.0, 0.0, 1.0], (m, 1))
    length = np.concatenate(([0.0], np.cumsum(np.linalg.norm(np.diff(points, axis=0), axis=1))))
    behind = np.clip(np.searchsorted(length, length - half_window_A, side="right") - 1, 0, m - 1)
    ahead = np.clip(np.searchsorted(length, length + half_window_A, side="left"), 0, m - 1)
    chord = points[ahead] - points[behind]
    norm = np.linalg.norm(chord, axis=1)
    good = np.flatnonzero(norm > 1e-9)
    if good.size == 0:
        return np.tile([0.0, 0.0, 1.0], (m, 1))
    k = np.arange(m)
    after = good[np.clip(np.searchsorted(good, k), 0, good.size - 1)]
    before = good[np.clip(np.searchsorted(good, k) - 1, 0, good.size - 1)]
    pick = np.where(np.abs(before - k) < np.abs(after - k), before, after)
    return chord[pick] / norm[pick][:, None]
