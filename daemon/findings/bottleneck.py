"""Clearance and passage radius along the explored path, and the path's bottleneck.

At every path point: the clearance (distance from the probe centre to the nearest vdW
surface: the probe radius wherever the probe touched) and the passage radius (the widest
sphere centred in the plane across the direction of travel: molecule/clearance.py).

A passage counts only where it bounds the path over MIN_RUN_A of travel or more
(molecule/clearance.py says why). The bottleneck is the narrowest counted passage while
in contact: the places where the hand felt walls. Around the narrowest path point it is
refined on the raw ticks between its neighbours (each with its nearest point's
direction), and the refined tick joins the path, so a coarse path never steps over the
narrowest place and the chart shows what the verdict says. A probe of radius r passes when
the bottleneck is at least r (to round-off, ROUND_OFF_A): then it fits everywhere along
the explored path.
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
    profile with its refined tick in them."""
    candidates = np.flatnonzero(path.contact & prof.bounded)
    if candidates.size == 0:
        return None, path, prof
    j = int(candidates[np.argmin(prof.passage_A[candidates])])
    best_tick, best = int(path.ticks[j]), prof.passage[j]
    lo, hi = max(j - 1, 0), min(j + 1, path.n_points - 1)
    between = np.arange(path.ticks[lo], path.ticks[hi] + 1)
    between = between[track.contact[between] & ~np.isin(between, path.ticks)]
    if between.size > REFINE_TICKS:
        between = between[np.linspace(0, between.size - 1, REFINE_TICKS).round().astype(int)]
    direction_of = {}
    for tick in between:
        nearest = lo + int(np.argmin(np.abs(path.ticks[lo : hi + 1] - tick)))
        direction_of[int(tick)] = path.direction[nearest]
        trial = field.passage(track.proxy_A[tick], direction_of[int(tick)])
        if not trial.open and trial.radius_A < best.radius_A:
            best_tick, best = int(tick), trial
    if best_tick not in path.ticks:
        path, prof, j = _with_tick(
            track, path, prof, field, best_tick, direction_of[best_tick], best
        )
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
        "t_s": float(track.t_s[best_tick]),
        "seq": int(track.seq[best_tick]),
        "path_length_A": float(path.length_A[j]),
        "probe_position_A": track.proxy_A[best_tick].tolist(),
        "center_A": best.center_A.tolist(),
        "atoms": atoms,
    }
    return neck, path, prof


def _with_tick(
    track: Track,
    path: ExploredPath,
    prof: Profile,
    field: ClearanceField,
    tick: int,
    direction: np.ndarray,
    passage: Passage,
) -> tuple[ExploredPath, Profile, int]:
    """The path and profile with one more point, at a raw tick (and its index)."""
    k = int(np.searchsorted(path.ticks, tick))
    ticks = np.insert(path.ticks, k, tick)
    pos = track.proxy_A[ticks]
    starts = np.concatenate(([0], ticks[:-1] + 1))
    length = np.concatenate(([0.0], np.cumsum(np.linalg.norm(np.diff(pos, axis=0), axis=1))))
    new_path = replace(
        path,
        ticks=ticks,
        position_A=pos,
        t_s=track.t_s[ticks],
        contact=np.logical_or.reduceat(track.contact, starts),
        force_max_N=np.maximum.reduceat(track.force_N, starts),
        length_A=length,
        direction=np.insert(path.direction, k, direction, axis=0),
    )
    clearance = np.insert(prof.clearance_A, k, field.clearance(track.proxy_A[tick])[0][0])
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
        "verdict": f"a {probe_radius_A:g} Å probe {how} through the bottleneck of "
        f"{bottleneck_A:.2f} Å",
    }
