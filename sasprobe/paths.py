"""Where the shared test and benchmark structures live.

The checkout sits beside a `shared/` folder (`../shared/data/pdb/` from the repo root).
`SASPROBE_DATA` overrides the search.
"""

from __future__ import annotations

import csv
import os
from dataclasses import dataclass
from pathlib import Path

_REPO_ROOT = Path(__file__).resolve().parent.parent


def shared_pdb_dir() -> Path | None:
    """The folder of shared PDB/mmCIF files, or None when it is not beside this checkout."""
    env = os.environ.get("SASPROBE_DATA")
    if env:
        path = Path(env)
        return path if path.is_dir() else None
    for base in (Path.cwd(), _REPO_ROOT):
        for candidate in (base.parent / "shared" / "data" / "pdb", base / "shared" / "data" / "pdb"):
            if candidate.is_dir():
                return candidate
    return None


@dataclass(frozen=True)
class SharedEntry:
    id: str
    path: Path
    format: str
    atoms: int  # atom records in the file as the manifest counts them (all models, waters)
    note: str


def shared_structures() -> list[SharedEntry]:
    """Entries of the shared MANIFEST.tsv, smallest first; empty when the folder is absent."""
    folder = shared_pdb_dir()
    if folder is None or not (folder / "MANIFEST.tsv").is_file():
        return []
    with open(folder / "MANIFEST.tsv", newline="") as fh:
        rows = list(csv.DictReader(fh, delimiter="\t"))
    entries = [
        SharedEntry(
            id=row["id"],
            path=folder / row["file"],
            format=row["format"],
            atoms=int(row["atoms"]),
            note=row["protein_heavy_atoms_or_note"],
        )
        for row in rows
    ]
    return sorted(entries, key=lambda e: e.atoms)
