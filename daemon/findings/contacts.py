"""Which residues the probe touched, for how long and how hard, and which lie at each mark.

A contact tick touches every atom whose SAS sphere (vdW + probe radius) the probe centre
lies on, within CONTACT_TOLERANCE_A (the proxy rests on one, two or three spheres; the
pose names only the first, which is always counted). A residue's contact time is the
time of its contact ticks (a tick touching two of its atoms counts once), its largest
force the largest |force| of those ticks. The residues at a mark are those with an atom
centre within MARK_RADIUS_A of it.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
from sasprobe.daemon.findings.session import Track
from sasprobe.molecule import Structure
from sasprobe.molecule.clearance import ClearanceField

CONTACT_TOLERANCE_A = 0.01
MARK_RADIUS_A = 4.0


def residue_of(structure: Structure, atom: int) -> dict:
    """Chain, residue name, number and insertion code of an atom."""
    return {
        "chain": str(structure.chain_ids[atom]),
        "name": str(structure.residue_names[atom]),
        "number": int(structure.residue_numbers[atom]),
        "icode": str(structure.insertion_codes[atom]),
    }


def _residue_key(structure: Structure, atom: int) -> tuple:
    return (
        str(structure.chain_ids[atom]),
        int(structure.residue_numbers[atom]),
        str(structure.insertion_codes[atom]),
        str(structure.residue_names[atom]),
    )


def touched_atoms_per_tick(
    track: Track, field: ClearanceField, progress: Callable[[int], None] | None = None
) -> dict[int, list[int]]:
    """Contact tick index -> the atoms touched then (ticks at an unchanged position share one
    query)."""
    reach = track.probe_radius_A + CONTACT_TOLERANCE_A
    out: dict[int, list[int]] = {}
    previous = None
    atoms: list[int] = []
    for i in np.flatnonzero(track.contact):
        p = track.proxy_A[i]
        if previous is None or not np.array_equal(p, previous):
            atoms = field.grid.spheres_within(p, reach).tolist()
            previous = p
        recorded = int(track.touched_atom[i])
        out[int(i)] = atoms if recorded < 0 or recorded in atoms else [recorded, *atoms]
        if progress is not None:
            progress(1)
    return out


def touched_residues(track: Track, per_tick: dict[int, list[int]]) -> list[dict]:
    """One row per residue touched, in the order they were first touched."""
    s = track.structure
    rows: dict[tuple, dict] = {}
    for i, atoms in per_tick.items():
        t, force = float(track.t_s[i]), float(track.force_N[i])
        seen = set()
        for atom in atoms:
            key = _residue_key(s, atom)
            row = rows.get(key)
            if row is None:
                row = rows[key] = {
                    **residue_of(s, atom),
                    "atoms": {},
                    "contact_s": 0.0,
                    "max_force_N": 0.0,
                    "first_s": t,
                    "last_s": t,
                }
            name = str(s.atom_names[atom])
            row["atoms"][name] = row["atoms"].get(name, 0) + 1
            if key not in seen:
                seen.add(key)
                row["contact_s"] += float(track.dt_s[i])
                row["max_force_N"] = max(row["max_force_N"], force)
                row["first_s"], row["last_s"] = min(row["first_s"], t), max(row["last_s"], t)
    out = []
    for row in sorted(rows.values(), key=lambda r: r["first_s"]):
        atoms = sorted(row.pop("atoms").items(), key=lambda kv: (-kv[1], kv[0]))
        out.append({**row, "atoms": [name for name, _ in atoms]})
    return out


def residues_near(structure: Structure, point, radius_A: float = MARK_RADIUS_A) -> list[dict]:
    """Residues with an atom centre within radius_A of a point, nearest first, with that
    distance."""
    dist = np.linalg.norm(structure.positions - np.asarray(point, dtype=np.float64), axis=1)
    best: dict[tuple, tuple[float, int]] = {}
    for atom in np.flatnonzero(dist <= radius_A):
        key = _residue_key(structure, int(atom))
        if key not in best or dist[atom] < best[key][0]:
            best[key] = (float(dist[atom]), int(atom))
    return [
        {
            **residue_of(structure, atom),
            "nearest_atom": str(structure.atom_names[atom]),
            "distance_A": d,
        }
        for d, atom in sorted(best.values())
    ]
