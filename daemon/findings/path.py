"""The explored path: the probe's track decimated to points about a fixed distance apart,
without losing a contact, in one pass over the ticks.

A tick is kept when the probe has moved SPACING_A since the last kept one; where it
wedges between three atoms or more (its centre pinned where their SAS spheres meet: where
passages close around it), unless the last kept point is that same wedge within
PIN_SPACING_A; and always where a mark was dropped and at both ends. Each point stands
for the ticks since the one before: it is in contact when any of them was and carries
their largest force, so no contact and no force peak is lost (a push in one place is a
force peak, not a distance).

The path holds MAX_POINTS points at most, whatever the session's length: when a tick
would make it longer, both spacings widen by WIDEN and the points kept so far are
decimated again by the same rule (a point dropped hands its ticks, contact and force to
the next one kept), and the ticks after go on at the wider spacing. Past MAX_WIDEN a
change of wedge alone no longer keeps a point (only the pin spacing does), so a probe
rocking between wedges for hours cannot outgrow the bound either.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

SPACING_A = 0.25
PIN_SPACING_A = 0.05  # a probe rocking in a pocket re-enters the same wedge every few ticks
MAX_POINTS = 4000  # path points (the PDB export numbers them; the passage analysis costs ms each)
WIDEN = 1.5
MAX_WIDEN = 1e6


@dataclass
class ExploredPath:
    ticks: np.ndarray  # (M,) track indices of the kept ticks
    seq: np.ndarray  # (M,) their tick numbers
    position_A: np.ndarray  # (M, 3)
    t_s: np.ndarray  # (M,)
    contact: np.ndarray  # (M,) bool: some tick since the previous point touched the surface
    force_max_N: np.ndarray  # (M,) largest |force| over the ticks since the previous point
    length_A: np.ndarray  # (M,) distance travelled along the path up to the point
    direction: np.ndarray  # (M, 3) unit direction of travel
    spacing_A: float
    contact_ticks: np.ndarray  # (M,) contact ticks since the previous point, its own included
    own_contact: np.ndarray  # (M,) bool: the kept tick itself touched the surface

    @property
    def n_points(self) -> int:
        return int(self.ticks.size)


# A point: [tick, seq, (x, y, z), t_s, contact, force, contact ticks, own contact, forced,
# wedged, touched]; a span: [contact, force, contact ticks] of the ticks since the last point.
_TICK, _SEQ, _POS, _T, _CONTACT, _FORCE, _COUNT, _OWN, _FORCED, _WEDGED, _TOUCHED = range(11)


class PathBuilder:
    """Keeps the path's points as the ticks come, a block at a time."""

    def __init__(self, spacing_A: float = SPACING_A) -> None:
        self.base_spacing_A = spacing_A
        self.widen = 1.0
        self.points: list[list] = []
        self._span = [False, 0.0, 0]
        self._last_touched: frozenset = frozenset()  # of the tick before
        self._tail: list | None = None  # the newest tick, kept or not (the path's end)
        self._tail_kept = False

    def add_block(
        self,
        first: int,
        seq: list,
        points: list,
        t_s: list,
        contact: list,
        force: list,
        touched: list,
        marked: set,
    ) -> None:
        """Ticks first, first + 1, ...: their numbers, probe centres, times, contact, |force|,
        touched atoms, and the rows where a mark was dropped."""
        spacing = self.base_spacing_A * self.widen
        pin = PIN_SPACING_A * self.widen
        wedges_keep = self.widen <= MAX_WIDEN
        kept = self.points
        span = self._span
        before = self._last_touched
        last = kept[-1] if kept else None
        for row, point in enumerate(points):
            now = touched[row]
            wedged = len(now) >= 3 and now != before
            before = now
            touching = contact[row]
            if touching:
                span[0] = True
                span[2] += 1
            if force[row] > span[1]:
                span[1] = force[row]
            forced = last is None or row in marked
            moved = math.dist(point, last[_POS]) if last is not None else 0.0
            tick = [
                first + row,
                seq[row],
                point,
                t_s[row],
                span[0],
                span[1],
                span[2],
                touching,
                forced,
                wedged,
                now,
            ]
            if (
                forced
                or moved >= spacing
                or (wedged and ((wedges_keep and now != last[_TOUCHED]) or moved >= pin))
            ):
                kept.append(tick)
                last = tick
                span[:] = [False, 0.0, 0]
                self._tail_kept = True
                if len(kept) > MAX_POINTS:
                    self._last_touched = before
                    self._tail = tick
                    self._narrow()
                    self.add_block(
                        first + row + 1,
                        seq[row + 1 :],
                        points[row + 1 :],
                        t_s[row + 1 :],
                        contact[row + 1 :],
                        force[row + 1 :],
                        touched[row + 1 :],
                        {m - row - 1 for m in marked if m > row},
                    )
                    return
            else:
                self._tail_kept = False
            self._tail = tick
        self._last_touched = before

    def _narrow(self) -> None:
        """Widen the spacings until the points kept so far, decimated again, fit."""
        while len(self.points) > MAX_POINTS and self.widen <= MAX_WIDEN:
            self.widen *= WIDEN
            self.points, tail_span = _decimate(
                self.points,
                self.base_spacing_A * self.widen,
                PIN_SPACING_A * self.widen,
                self.widen <= MAX_WIDEN,
            )
            if tail_span is not None:  # the newest point was dropped: its ticks wait for the next
                self._span = tail_span
                self._tail_kept = False

    def finish(self) -> ExploredPath:
        """The path, its last tick kept (an empty track has no path)."""
        if self._tail is not None and not self._tail_kept:
            self.points.append(self._tail)
            self._tail_kept = True
            if len(self.points) > MAX_POINTS:
                self._narrow()
        pts = self.points
        pos = np.array([p[_POS] for p in pts], dtype=np.float64).reshape(-1, 3)
        length = np.concatenate(([0.0], np.cumsum(np.linalg.norm(np.diff(pos, axis=0), axis=1))))
        return ExploredPath(
            ticks=np.array([p[_TICK] for p in pts], dtype=np.int64),
            seq=np.array([p[_SEQ] for p in pts], dtype=np.int64),
            position_A=pos,
            t_s=np.array([p[_T] for p in pts], dtype=np.float64),
            contact=np.array([p[_CONTACT] for p in pts], dtype=bool),
            force_max_N=np.array([p[_FORCE] for p in pts], dtype=np.float64),
            length_A=length[: len(pts)],
            direction=travel_directions(pos),
            spacing_A=self.base_spacing_A * self.widen,
            contact_ticks=np.array([p[_COUNT] for p in pts], dtype=np.int64),
            own_contact=np.array([p[_OWN] for p in pts], dtype=bool),
        )


def _decimate(
    points: list[list], spacing: float, pin: float, wedges_keep: bool
) -> tuple[list[list], list | None]:
    """The points the rule keeps at a wider spacing, each with the spans of those dropped
    before it folded in; and the span of the dropped ones after the last point kept (None
    when the newest point stays)."""
    kept: list[list] = []
    span = [False, 0.0, 0]
    for p in points:
        span[0] = span[0] or p[_CONTACT]
        span[1] = max(span[1], p[_FORCE])
        span[2] += p[_COUNT]
        last = kept[-1] if kept else None
        moved = math.dist(p[_POS], last[_POS]) if last is not None else 0.0
        if (
            last is None
            or p[_FORCED]
            or moved >= spacing
            or (p[_WEDGED] and ((wedges_keep and p[_TOUCHED] != last[_TOUCHED]) or moved >= pin))
        ):
            kept.append([*p[:_CONTACT], span[0], span[1], span[2], *p[_OWN:]])
            span = [False, 0.0, 0]
    return kept, (span if kept[-1][_TICK] != points[-1][_TICK] else None)


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
