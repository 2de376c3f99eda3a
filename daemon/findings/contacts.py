"""Which residues the probe touched, for how long and how hard, and which lie at each mark.

A contact tick touches every atom whose SAS sphere (vdW + probe radius) the probe centre
lies on, within CONTACT_TOLERANCE_A (the proxy rests on one, two or three spheres; the
pose names only the first, which is always counted). A residue's contact time is the
time of its contact ticks (a tick touching two of its atoms counts once), its largest
force the largest |force| of those ticks. The residues at a mark are those with an atom
centre within MARK_RADIUS_A of it. `Contacts` takes the track a block at a time and
keeps one row per residue touched.
"""

from __future__ import annotations

import numpy as np
from sasprobe.daemon.findings.session import TrackBlock
from sasprobe.molecule import Structure
from sasprobe.molecule.clearance import ClearanceField

CONTACT_TOLERANCE_A = 0.01
MARK_RADIUS_A = 4.0
_NONE: frozenset = frozenset()


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


class Contacts:
    """The atoms each contact tick touches, and the touched residues' rows so far."""

    def __init__(self, structure: Structure, field: ClearanceField, probe_radius_A: float) -> None:
        self.structure = structure
        self._grid = field.grid
        self._reach = probe_radius_A + CONTACT_TOLERANCE_A
        self._previous: np.ndarray | None = None  # ticks at an unchanged position share a query
        self._atoms: list[int] = []
        self._rows: dict[tuple, dict] = {}
        self._keys: dict[int, tuple] = {}  # atom -> its residue's key

    def block(self, block: TrackBlock) -> list[frozenset]:
        """The atoms each tick of a block touches (none for a tick not in contact)."""
        out = [_NONE] * len(block)
        s = self.structure
        for i in np.flatnonzero(block.contact).tolist():
            p = block.proxy_A[i]
            if self._previous is None or not np.array_equal(p, self._previous):
                self._atoms = self._grid.spheres_within(p, self._reach).tolist()
                self._previous = p
            recorded = int(block.touched_atom[i])
            atoms = (
                self._atoms if recorded < 0 or recorded in self._atoms else [recorded, *self._atoms]
            )
            out[i] = frozenset(atoms)
            t, force, dt = float(block.t_s[i]), float(block.force_N[i]), float(block.dt_s[i])
            seen = set()
            for atom in atoms:
                key = self._keys.get(atom)
                if key is None:
                    key = self._keys[atom] = _residue_key(s, atom)
                row = self._rows.get(key)
                if row is None:
                    row = self._rows[key] = {
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
                    row["contact_s"] += dt
                    row["max_force_N"] = max(row["max_force_N"], force)
                    row["first_s"], row["last_s"] = min(row["first_s"], t), max(row["last_s"], t)
        return out

    def residues(self) -> list[dict]:
        """One row per residue touched, in the order they were first touched."""
        out = []
        for row in sorted(self._rows.values(), key=lambda r: r["first_s"]):
            atoms = sorted(row["atoms"].items(), key=lambda kv: (-kv[1], kv[0]))
            out.append({**row, "atoms": [name for name, _ in atoms]})
        return out


def residues_near(structure: Structure, point, radius_A: float = MARK_RADIUS_A) -> list[dict]:
    """Residues with an atom centre within radius_A of a point, nearest first, with how far."""
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
