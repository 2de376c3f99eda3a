"""Clearance and passage radius along the explored path, and the path's bottleneck.

At every path point: the clearance (distance from the probe centre to the nearest vdW
surface: the probe radius wherever the probe touched) and the passage radius (the widest
sphere centred in the plane across the direction of travel: molecule/clearance.py).

A passage counts only where it bounds the path over MIN_RUN_A of travel or more
(molecule/clearance.py says why). The bottleneck is the narrowest counted passage while in
contact: the places where the hand felt walls. Around the narrowest path point it is
refined on the raw ticks between its neighbours (each with its nearest point's
direction; a second pass over the track reads them, up to the later neighbour), and the
refined tick joins the path, so a coarse path never steps over the narrowest place and
the chart shows what the verdict says. A probe of radius r passes when the bottleneck is at least
r (to round-off, ROUND_OFF_A): then it fits everywhere along the explored path.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, replace

import numpy as np
from sasprobe.daemon.findings.contacts import residue_of
from sasprobe.daemon.findings.path import ExploredPath
from sasprobe.daemon.findings.session import Track
from sasprobe.molecule.clearance import OPEN_RADIUS_A, ClearanceField, Passage, persistent

ROUND_OFF_A = 1e-9
REFINE_TICKS = 64  # raw ticks tried around the narrowest path point


@dataclass
class Profile:
    clearance_A: np.ndarray  # (M,) at each path point
    passage: list[Passage]  # (M,)
    bounded: np.ndarray  # (M,) bool: a counted passage bounds the path here

    @property
    def passage_A(self) -> np.ndarray:
        """The passage radius where it counts, OPEN_RADIUS_A elsewhere."""
        return np.where(self.bounded, [p.radius_A for p in self.passage], OPEN_RADIUS_A)


def profile(
    path: ExploredPath, field: ClearanceField, progress: Callable[[int], None] | None = None
) -> Profile:
    clearance, _ = field.clearance(path.position_A)
    passages = []
    for point, direction in zip(path.position_A, path.direction):
        passages.append(field.passage(point, direction))
        if progress is not None:
            progress(1)
    bounded = persistent(~np.array([p.open for p in passages], dtype=bool), path.length_A)
    return Profile(clearance, passages, bounded)


def bottleneck(
    track: Track, path: ExploredPath, prof: Profile, field: ClearanceField
) -> tuple[dict | None, ExploredPath, Profile]:
    """The narrowest counted passage in contact (None when there is none), and the path and
    profile with its refined tick in them (the raw ticks come from a second, partial pass)."""
    candidates = np.flatnonzero(path.contact & prof.bounded)
    if candidates.size == 0:
        return None, path, prof
    j = int(candidates[np.argmin(prof.passage_A[candidates])])
    best, best_raw = prof.passage[j], None
    lo, hi = max(j - 1, 0), min(j + 1, path.n_points - 1)
    for tick in _raw_ticks(track, path, lo, hi):
        nearest = lo + int(np.argmin(np.abs(path.ticks[lo : hi + 1] - tick.index)))
        tick.direction = path.direction[nearest]
        trial = field.passage(tick.proxy_A, tick.direction)
        if not trial.open and trial.radius_A < best.radius_A:
            best, best_raw = trial, tick
    if best_raw is not None:
        path, prof, j = _with_tick(path, prof, field, best_raw, best)
    s = track.structure
    atoms = []
    for atom in best.atoms:
        d = float(np.linalg.norm(best.center_A - s.positions[atom]) - s.vdw_radii[atom])
        atoms.append(
            {
                **residue_of(s, int(atom)),
                "atom": str(s.atom_names[atom]),
                "index": int(atom),
                "surface_distance_A": d,
            }
        )
    neck = {
        "radius_A": best.radius_A,
        "t_s": float(path.t_s[j]),
        "seq": int(path.seq[j]),
        "path_length_A": float(path.length_A[j]),
        "probe_position_A": path.position_A[j].tolist(),
        "center_A": best.center_A.tolist(),
        "atoms": atoms,
    }
    return neck, path, prof


@dataclass
class _RawTick:
    """A contact tick between path points, with what the path needs to take it in: the
    (contact, largest force, contact ticks) of the ticks it would stand for, and of those
    the path point after it would stand for then."""

    index: int  # track index
    seq: int
    t_s: float
    proxy_A: np.ndarray
    before: tuple = (False, 0.0, 0)
    after: tuple = (False, 0.0, 0)
    direction: np.ndarray | None = None


def _combined(pieces: list[tuple]) -> tuple:
    return (
        any(p[0] for p in pieces),
        max((p[1] for p in pieces), default=0.0),
        sum(p[2] for p in pieces),
    )


def _raw_ticks(track: Track, path: ExploredPath, lo: int, hi: int) -> list[_RawTick]:
    """The contact ticks between path points lo and hi that are not path points, at most
    REFINE_TICKS of them evenly spread, read from the track up to point hi."""
    count = int(np.sum(path.contact_ticks[lo + 1 : hi + 1] - path.own_contact[lo + 1 : hi + 1]))
    if count == 0:
        return []
    wanted = np.arange(count)
    if count > REFINE_TICKS:
        wanted = np.linspace(0, count - 1, REFINE_TICKS).round().astype(int)
    wanted_set = set(wanted.tolist())
    start, stop = int(path.ticks[lo]), int(path.ticks[hi])
    on_path = set(path.ticks[lo : hi + 1].tolist())
    found: list[_RawTick] = []
    # Boundaries after `start` (path points and raw ticks, in order): (raw tick or None, the
    # (contact, force, contact ticks) of the ticks since the boundary before).
    bounds: list[tuple[_RawTick | None, tuple]] = []
    piece = [False, 0.0, 0]
    seen = 0
    blocks = track.blocks()
    try:
        for block in blocks:
            end = block.first + len(block)
            if end <= start + 1:
                continue
            for row in range(
                max(start + 1 - block.first, 0), min(stop + 1 - block.first, len(block))
            ):
                index = block.first + row
                touching = bool(block.contact[row])
                piece[0] = piece[0] or touching
                piece[1] = max(piece[1], float(block.force_N[row]))
                piece[2] += touching
                if index in on_path:
                    bounds.append((None, tuple(piece)))
                    piece = [False, 0.0, 0]
                elif touching:
                    if seen in wanted_set:
                        tick = _RawTick(
                            index,
                            int(block.seq[row]),
                            float(block.t_s[row]),
                            np.array(block.proxy_A[row]),
                        )
                        found.append(tick)
                        bounds.append((tick, tuple(piece)))
                        piece = [False, 0.0, 0]
                    seen += 1
            if end > stop:
                break
    finally:
        blocks.close()
    for b, (tick, _) in enumerate(bounds):
        if tick is None:
            continue
        first = b
        while first > 0 and bounds[first - 1][0] is not None:
            first -= 1
        last = b + 1
        while last < len(bounds) - 1 and bounds[last][0] is not None:
            last += 1
        tick.before = _combined([p for _, p in bounds[first : b + 1]])
        tick.after = _combined([p for _, p in bounds[b + 1 : last + 1]])
    return found


def _with_tick(
    path: ExploredPath, prof: Profile, field: ClearanceField, tick: _RawTick, passage: Passage
) -> tuple[ExploredPath, Profile, int]:
    """The path and profile with one more point, at a raw tick (and its index)."""
    k = int(np.searchsorted(path.ticks, tick.index))
    pos = np.insert(path.position_A, k, tick.proxy_A, axis=0)
    length = np.concatenate(([0.0], np.cumsum(np.linalg.norm(np.diff(pos, axis=0), axis=1))))
    contact = np.insert(path.contact, k, tick.before[0])
    force = np.insert(path.force_max_N, k, tick.before[1])
    counts = np.insert(path.contact_ticks, k, tick.before[2])
    contact[k + 1], force[k + 1], counts[k + 1] = tick.after  # the point after: its ticks since
    new_path = replace(
        path,
        ticks=np.insert(path.ticks, k, tick.index),
        seq=np.insert(path.seq, k, tick.seq),
        position_A=pos,
        t_s=np.insert(path.t_s, k, tick.t_s),
        contact=contact,
        force_max_N=force,
        length_A=length,
        direction=np.insert(path.direction, k, tick.direction, axis=0),
        contact_ticks=counts,
        own_contact=np.insert(path.own_contact, k, True),
    )
    clearance = np.insert(prof.clearance_A, k, field.clearance(tick.proxy_A)[0][0])
    new_prof = Profile(
        clearance, [*prof.passage[:k], passage, *prof.passage[k:]], np.insert(prof.bounded, k, True)
    )
    return new_path, new_prof, k


def verdict(bottleneck_A: float | None, probe_radius_A: float) -> dict:
    """Whether a probe of this radius fits everywhere along the explored path."""
    if bottleneck_A is None:
        return {
            "probe_radius_A": probe_radius_A,
            "passes": True,
            "verdict": f"no passage narrower than {OPEN_RADIUS_A:g} Å where the probe touched: "
            f"a {probe_radius_A:g} Å probe fits all along the path",
        }
    passes = bottleneck_A >= probe_radius_A - ROUND_OFF_A
    how = "fits" if passes else "does not fit"
    return {
        "probe_radius_A": probe_radius_A,
        "passes": bool(passes),
        "verdict": (
            f"a {probe_radius_A:g} Å probe {how} through the bottleneck of {bottleneck_A:.2f} Å"
        ),
    }
