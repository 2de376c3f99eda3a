"""Backbone trace: one atom per residue (C-alpha for amino acids, P for nucleotides).

Consecutive trace atoms of a chain are joined unless they are further apart than a
chain break allows: 4.2 Å for CA-CA (trans peptides are 3.8 Å apart), 8.0 Å for P-P
(5.5-7.5 Å along a nucleic-acid strand), and never across a protein/nucleic switch.
Segments of one atom are kept, so a lone residue is still shown.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np
from sasprobe.molecule.residues import residue_kind

if TYPE_CHECKING:
    from sasprobe.molecule.structure import Structure

MAX_CA_GAP = 4.2  # Å
MAX_P_GAP = 8.0  # Å


def trace_segments(structure: Structure) -> tuple[list[np.ndarray], list[str]]:
    """Segments of trace-atom indices (in file order) and the chain of each."""
    names = structure.atom_names
    candidates = np.flatnonzero((names == "CA") | (names == "P"))
    if candidates.size == 0:
        return [], []
    kinds = np.array([residue_kind(str(r)) for r in structure.residue_names[candidates]])
    is_ca = (
        (names[candidates] == "CA") & (kinds == "protein") & (structure.elements[candidates] == "C")
    )
    is_p = (names[candidates] == "P") & (kinds == "nucleic")
    trace = candidates[is_ca | is_p]
    if trace.size == 0:
        return [], []
    protein = names[trace] == "CA"
    chains = structure.chain_ids[trace]
    gaps = np.linalg.norm(np.diff(structure.positions[trace], axis=0), axis=1)
    same_kind = protein[1:] == protein[:-1]
    limit = np.where(protein[1:], MAX_CA_GAP, MAX_P_GAP)
    joined = (chains[1:] == chains[:-1]) & same_kind & (gaps <= limit)
    starts = np.concatenate(([0], np.flatnonzero(~joined) + 1))
    segments = np.split(trace, starts[1:])
    return segments, [str(chains[s]) for s in starts]
