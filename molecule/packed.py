"""A parsed structure as flat arrays: what a renderer following a daemon needs of it,
without parsing the file again (the daemon serves it: `get_structure` with
`"form": "arrays"`, protocol/README.md). Unpacking 6ZU5 (165,175 atoms) takes a tenth of
the time parsing its mmCIF file does.

Layout: a NumPy .npz archive (numpy.savez, uncompressed; nothing pickled, read with
allow_pickle=False) of

    positions                         float64 (N, 3)        Å, molecule frame
    residue_numbers                   int32 (N,)            auth sequence numbers
    is_hetero                         bool (N,)             HETATM
    b_factors                         float64 (N,)          isotropic B, Å²
    <text>_values, <text>_index       str (K,), int32 (N,)  the distinct values and each atom's
                                                            index into them, for elements,
                                                            chain_ids, residue_names,
                                                            insertion_codes, atom_names
    backbone_atoms, backbone_lengths  int64 (M,), int64 (S,)  the trace's segments,
                                                            concatenated, and their lengths
    backbone_chains                   str (S,)              each segment's chain

Radii and colours follow from the elements (molecule/elements.py), as parsing makes them.
"""

from __future__ import annotations

import io
import zipfile

import numpy as np
from sasprobe.molecule.elements import colors_for, radii_for
from sasprobe.molecule.loading import parse_structure
from sasprobe.molecule.structure import MAX_COORDINATE_A, Structure, StructureError

TEXT_FIELDS = ("elements", "chain_ids", "residue_names", "insertion_codes", "atom_names")


def pack_structure(structure: Structure) -> bytes:
    """The arrays of `structure` in the layout above."""
    arrays = {
        "positions": np.asarray(structure.positions, dtype=np.float64),
        "residue_numbers": np.asarray(structure.residue_numbers, dtype=np.int32),
        "is_hetero": np.asarray(structure.is_hetero, dtype=bool),
        "b_factors": np.asarray(structure.b_factors, dtype=np.float64),
        "backbone_atoms": np.concatenate(
            [np.asarray(s, dtype=np.int64) for s in structure.backbone]
        )
        if structure.backbone
        else np.zeros(0, dtype=np.int64),
        "backbone_lengths": np.array([len(s) for s in structure.backbone], dtype=np.int64),
        "backbone_chains": np.asarray(structure.backbone_chains, dtype=str),
    }
    for name in TEXT_FIELDS:
        values, index = np.unique(
            np.asarray(getattr(structure, name), dtype=str), return_inverse=True
        )
        arrays[f"{name}_values"], arrays[f"{name}_index"] = values, index.astype(np.int32)
    out = io.BytesIO()
    np.savez(out, **arrays)
    return out.getvalue()


def unpack_structure(data: bytes, name: str, source: str, sha256: str) -> Structure:
    """A Structure from pack_structure's bytes (`sha256`: of the file it was parsed from,
    which names the structure); StructureError naming `source` when they do not hold a
    structure in the layout above."""
    try:
        with np.load(io.BytesIO(data), allow_pickle=False) as archive:
            arrays = {key: archive[key] for key in archive.files}
    except (OSError, ValueError, EOFError, zipfile.BadZipFile) as exc:
        raise StructureError(f"{source}: not a packed structure ({exc})") from None
    try:
        return _structure(arrays, name, source, sha256)
    except (KeyError, IndexError, ValueError, TypeError) as exc:
        raise StructureError(f"{source}: a packed structure with bad arrays ({exc})") from None


def _structure(a: dict, name: str, source: str, sha256: str) -> Structure:
    positions = a["positions"]
    if (
        positions.dtype != np.float64
        or positions.ndim != 2
        or positions.shape[1] != 3
        or positions.shape[0] == 0
    ):
        raise ValueError("positions must be float64 (N, 3), N > 0")
    if not (np.isfinite(positions).all() and np.abs(positions).max() <= MAX_COORDINATE_A):
        raise ValueError(f"coordinates must be finite and within ±{MAX_COORDINATE_A:g} Å")
    n = positions.shape[0]
    text, index_of = {}, {}
    for field in TEXT_FIELDS:
        values, index = a[f"{field}_values"], a[f"{field}_index"]
        if values.dtype.kind != "U" or index.shape != (n,) or index.dtype.kind not in "iu":
            raise ValueError(f"{field}: text values and one index per atom")
        if n and (index.min() < 0 or index.max() >= values.size):
            raise ValueError(f"{field}: an index beyond its {values.size} values")
        text[field], index_of[field] = values[index], index
    per_atom = {"residue_numbers": np.int32, "is_hetero": np.bool_, "b_factors": np.float64}
    for field, dtype in per_atom.items():
        if a[field].shape != (n,) or a[field].dtype != dtype:
            raise ValueError(f"{field}: one {np.dtype(dtype).name} per atom")
    atoms, lengths, chains = a["backbone_atoms"], a["backbone_lengths"], a["backbone_chains"]
    if (
        lengths.sum() != atoms.size
        or chains.shape != lengths.shape
        or (lengths < 0).any()
        or (atoms.size and (atoms.min() < 0 or atoms.max() >= n))
    ):
        raise ValueError("the backbone's segments do not fit its atoms")
    # radii and colours looked up per element
    symbols, of_atom = (a["elements_values"], index_of["elements"])
    return Structure(
        name=name,
        source=source,
        source_bytes=b"",
        sha256=sha256,
        positions=positions,
        elements=text["elements"],
        vdw_radii=radii_for(symbols)[of_atom],
        colors=colors_for(symbols)[of_atom],
        chain_ids=text["chain_ids"],
        residue_names=text["residue_names"],
        residue_numbers=a["residue_numbers"],
        insertion_codes=text["insertion_codes"],
        atom_names=text["atom_names"],
        is_hetero=a["is_hetero"],
        b_factors=a["b_factors"],
        backbone=[s.astype(np.int64) for s in np.split(atoms, np.cumsum(lengths)[:-1])]
        if lengths.size
        else [],
        backbone_chains=[str(c) for c in chains],
    )


def structure_from_served(served, keep_water: bool = False) -> Structure:
    """The structure a daemon served (`protocol.client.StructureFile`): its parsed arrays, or
    its file parsed with the waters when `keep_water` or the daemon kept them."""
    if served.form == "arrays":
        return unpack_structure(served.data, served.name, served.source, served.sha256)
    return parse_structure(
        served.data,
        name=served.name,
        source=served.source,
        keep_water=keep_water or served.keep_water,
    )
