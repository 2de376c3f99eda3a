"""A macromolecular structure as sasprobe holds it: one model as flat per-atom arrays in the
molecule frame (Å), the error every unusable structure file raises, and a structure's name
from its file's (the shipped default's too, which molecule/fetch.py answers an id with).
Reading a file into one is molecule/loading.py."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from sasprobe.molecule.probe import DEFAULT_PROBE_RADIUS

from sasprobe.common.errors import UserError

DEFAULT_STRUCTURE = "1crn.pdb.gz"  # shipped in data/: crambin, the structure of every default
# |x|, |y|, |z| in Å: the PDB format's own reach (8.3f), far beyond any assembly
MAX_COORDINATE_A = 10_000.0


class StructureError(UserError):
    """A structure file that cannot be used; the message names the file."""


@dataclass
class Structure:
    """One model of a structure as flat per-atom arrays (molecule frame, Å)."""

    name: str
    source: str  # file path, or "embedded:<file>"
    source_bytes: bytes = field(repr=False)  # the file exactly as read (served to remote renderers)
    sha256: str
    positions: np.ndarray  # (N, 3) float64, Å
    elements: np.ndarray  # (N,) str, e.g. "C", "Fe"; "X" when undeterminable
    vdw_radii: np.ndarray  # (N,) float64, Å (Bondi 1964, fallback 1.80 Å)
    colors: np.ndarray  # (N, 3) float32, CPK, 0..1
    chain_ids: np.ndarray  # (N,) str (auth chain id; may be several characters)
    residue_names: np.ndarray  # (N,) str
    residue_numbers: np.ndarray  # (N,) int32 (auth sequence number)
    insertion_codes: np.ndarray  # (N,) str ("" when none)
    atom_names: np.ndarray  # (N,) str
    is_hetero: np.ndarray  # (N,) bool (HETATM)
    b_factors: np.ndarray  # (N,) float64, isotropic B (Å²) as the file gives it
    backbone: list[np.ndarray]  # per segment: atom indices of the trace (CA or P), in order
    backbone_chains: list[str]  # chain id of each segment
    warnings: list[str] = field(default_factory=list)

    @property
    def n_atoms(self) -> int:
        return int(self.positions.shape[0])

    @property
    def n_chains(self) -> int:
        return int(np.unique(self.chain_ids).size)

    @property
    def n_residues(self) -> int:
        keys = np.char.add(
            np.char.add(self.chain_ids.astype(str), "\x00"),
            np.char.add(self.residue_numbers.astype(str), self.insertion_codes.astype(str)),
        )
        keys = np.char.add(np.char.add(keys, "\x00"), self.residue_names.astype(str))
        return int(np.unique(keys).size)

    def expanded_radii(self, probe_radius: float = DEFAULT_PROBE_RADIUS) -> np.ndarray:
        """Radii of the solvent-accessible spheres: van der Waals radius + probe radius."""
        return self.vdw_radii + float(probe_radius)

    def bbox(self) -> tuple[np.ndarray, np.ndarray]:
        """Axis-aligned bounds of the atom centres (Å)."""
        return self.positions.min(axis=0), self.positions.max(axis=0)


def structure_name(filename: str) -> str:
    """A structure's name from its file name: the stem without .gz/.pdb/.ent/.cif/.mmcif."""
    for suffix in (".gz", ".pdb", ".ent", ".cif", ".mmcif"):
        if filename.lower().endswith(suffix):
            filename = filename[: -len(suffix)]
    return filename
