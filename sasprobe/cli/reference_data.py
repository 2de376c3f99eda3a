"""The reference structures the tests and benchmarks use: `tests/data/pdb/` in the
checkout, listed in its MANIFEST.tsv (source and licence of each entry).

`SASPROBE_DATA=DIR` points at another folder with the same layout.
"""

from __future__ import annotations

import csv
import os
from dataclasses import dataclass
from pathlib import Path

REPO_ROOT = Path(__file__).resolve().parents[2]
DATA_ENV = "SASPROBE_DATA"
MISSING = (
    f"no reference structures found (expected tests/data/pdb/ in the checkout, or {DATA_ENV}=DIR)"
)


def reference_pdb_dir() -> Path | None:
    """The folder of reference PDB/mmCIF files, or None when there is none (an installed
    package has no tests/ folder; SASPROBE_DATA names one)."""
    env = os.environ.get(DATA_ENV)
    if env:
        path = Path(env)
        return path if path.is_dir() else None
    for base in (REPO_ROOT, Path.cwd()):
        candidate = base / "tests" / "data" / "pdb"
        if candidate.is_dir():
            return candidate
    return None


@dataclass(frozen=True)
class ReferenceEntry:
    id: str
    path: Path
    format: str
    atoms: int  # atom records in the file as the manifest counts them (all models, waters)
    note: str


def reference_structures() -> list[ReferenceEntry]:
    """Entries of MANIFEST.tsv, smallest first; empty when the folder is absent."""
    folder = reference_pdb_dir()
    if folder is None or not (folder / "MANIFEST.tsv").is_file():
        return []
    with open(folder / "MANIFEST.tsv", newline="") as fh:
        rows = list(csv.DictReader(fh, delimiter="\t"))
    entries = [
        ReferenceEntry(
            id=row["id"],
            path=folder / row["file"],
            format=row["format"],
            atoms=int(row["atoms"]),
            note=row["protein_heavy_atoms_or_note"],
        )
        for row in rows
    ]
    return sorted(entries, key=lambda e: e.atoms)
