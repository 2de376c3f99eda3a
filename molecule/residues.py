"""What each residue is: its kind (protein, nucleic acid, ligand, water, ion), where its
atoms start in the structure's arrays, its hydrophobicity, and per-residue sums.

Residue kinds come from gemmi's table of residues (`gemmi.find_tabulated_residue`: the
amino acids and nucleotides of the PDB's Chemical Component Dictionary, modified ones such
as MSE or PSU included). A residue the table does not call an amino acid, a nucleotide or
water is an *ion* when it has a single atom (Mg, Zn, Cl, Na, ...) and a *ligand*
otherwise (ADP, chlorophyll, sulphate, ...).

Hydrophobicity: the scale of J. Kyte and R. F. Doolittle, "A simple method for displaying
the hydropathic character of a protein", J. Mol. Biol. 157, 105-132 (1982):
the hydropathy index, −4.5 for arginine to +4.5 for isoleucine.
"""

from __future__ import annotations

from functools import cache
from typing import TYPE_CHECKING

import gemmi
import numpy as np

if TYPE_CHECKING:
    from sasprobe.molecule.structure import Structure

# The kinds, in the order their codes number them (residue_kinds returns these codes).
KINDS = ("protein", "nucleic", "ligand", "water", "ion")
PROTEIN, NUCLEIC, LIGAND, WATER, ION = range(len(KINDS))

KYTE_DOOLITTLE: dict[str, float] = {
    "ILE": 4.5, "VAL": 4.2, "LEU": 3.8, "PHE": 2.8, "CYS": 2.5, "MET": 1.9, "ALA": 1.8,
    "GLY": -0.4, "THR": -0.7, "SER": -0.8, "TRP": -0.9, "TYR": -1.3, "PRO": -1.6,
    "HIS": -3.2, "GLU": -3.5, "GLN": -3.5, "ASP": -3.5, "ASN": -3.5, "LYS": -3.9, "ARG": -4.5,
}  # fmt: skip
KYTE_DOOLITTLE_RANGE = (-4.5, 4.5)


@cache
def residue_kind(name: str) -> str:
    """'protein', 'nucleic', 'water' for a residue name in gemmi's table, '' otherwise
    (a ligand or an ion: which one depends on its atoms, see residue_kinds)."""
    info = gemmi.find_tabulated_residue(name)
    if info is None:
        return ""
    if info.is_amino_acid():
        return "protein"
    if info.is_nucleic_acid():
        return "nucleic"
    if info.is_water():
        return "water"
    return ""


def residue_starts(structure: Structure) -> np.ndarray:
    """Index of each residue's first atom (a residue's atoms are contiguous), int64, with
    n_atoms appended, so residue r holds atoms starts[r]:starts[r + 1]."""
    n = structure.n_atoms
    if n == 0:
        return np.zeros(1, dtype=np.int64)
    s = structure
    change = (
        (s.chain_ids[1:] != s.chain_ids[:-1])
        | (s.residue_numbers[1:] != s.residue_numbers[:-1])
        | (s.insertion_codes[1:] != s.insertion_codes[:-1])
        | (s.residue_names[1:] != s.residue_names[:-1])
    )
    return np.concatenate(([0], np.flatnonzero(change) + 1, [n])).astype(np.int64)


def residue_kinds(structure: Structure) -> np.ndarray:
    """Per atom, the code (index into KINDS) of its residue's kind, uint8."""
    starts = residue_starts(structure)
    names = structure.residue_names[starts[:-1]]
    sizes = np.diff(starts)
    table = {"protein": PROTEIN, "nucleic": NUCLEIC, "water": WATER}
    per_residue = np.array(
        [
            table.get(residue_kind(str(name)), ION if size == 1 else LIGAND)
            for name, size in zip(names, sizes)
        ],
        dtype=np.uint8,
    )
    return np.repeat(per_residue, sizes)


def hydropathy(structure: Structure) -> np.ndarray:
    """Per atom, the Kyte-Doolittle index of its residue; NaN outside the 20 amino acids."""
    unique, inverse = np.unique(structure.residue_names, return_inverse=True)
    table = np.array([KYTE_DOOLITTLE.get(str(name), np.nan) for name in unique], dtype=np.float64)
    return table[inverse.reshape(-1)]


def per_residue_sums(structure: Structure, **columns: np.ndarray) -> list[dict]:
    """One row per residue, in structure order: chain, number, insertion code, name, atoms,
    and the sum over its atoms of each per-atom column given (e.g. area=..., accessible=...)."""
    starts = residue_starts(structure)
    sums = {
        key: np.add.reduceat(np.asarray(v, dtype=np.float64), starts[:-1])
        if structure.n_atoms
        else []
        for key, v in columns.items()
    }
    s = structure
    return [
        {
            "chain": str(s.chain_ids[a]),
            "number": int(s.residue_numbers[a]),
            "icode": str(s.insertion_codes[a]),
            "residue": str(s.residue_names[a]),
            "atoms": int(b - a),
            **{k: float(v[r]) for k, v in sums.items()},
        }
        for r, (a, b) in enumerate(zip(starts[:-1], starts[1:]))
    ]


def touched_label(structure: Structure | None, atom: int) -> str | None:
    """'A THR 2 OG1' for an atom index (chain, residue name, number and insertion code, atom)."""
    if structure is None or not 0 <= atom < structure.n_atoms:
        return None
    s = structure
    number = f"{s.residue_numbers[atom]}{s.insertion_codes[atom]}"
    return f"{s.chain_ids[atom]} {s.residue_names[atom]} {number} {s.atom_names[atom]}"
