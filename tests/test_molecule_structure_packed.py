"""Packed structures (molecule/packed.py): unpacked, a structure's arrays are the parsed
file's, on a small and a large entry; bytes that are not a packed structure, or arrays
that do not fit together, are one StructureError naming the source."""

from __future__ import annotations

import io

import numpy as np
import pytest
from sasprobe.molecule import StructureError, load_structure
from sasprobe.molecule.packed import pack_structure, unpack_structure

FIELDS = (
    "positions",
    "elements",
    "vdw_radii",
    "colors",
    "chain_ids",
    "residue_names",
    "residue_numbers",
    "insertion_codes",
    "atom_names",
    "is_hetero",
    "b_factors",
)


@pytest.mark.parametrize("sid", ["1crn", "1aon"])
def test_unpacked_arrays_equal_the_parsed_files(reference_by_id, sid):
    parsed = load_structure(reference_by_id[sid].path)
    unpacked = unpack_structure(pack_structure(parsed), parsed.name, "daemon", parsed.sha256)
    for field in FIELDS:
        a, b = getattr(parsed, field), getattr(unpacked, field)
        assert a.dtype == b.dtype and np.array_equal(a, b), field
    assert unpacked.backbone_chains == parsed.backbone_chains
    assert len(unpacked.backbone) == len(parsed.backbone) > 0
    assert all(np.array_equal(a, b) for a, b in zip(unpacked.backbone, parsed.backbone))
    assert (unpacked.name, unpacked.sha256, unpacked.n_atoms) == (
        parsed.name,
        parsed.sha256,
        parsed.n_atoms,
    )


def _repacked(data: bytes, **changes) -> bytes:
    with np.load(io.BytesIO(data)) as archive:
        arrays = {k: archive[k] for k in archive.files}
    arrays.update(changes)
    arrays = {k: v for k, v in arrays.items() if v is not None}  # None: left out
    out = io.BytesIO()
    np.savez(out, **arrays)
    return out.getvalue()


def test_bad_packed_bytes_are_one_line_naming_the_source(crambin):
    good = pack_structure(crambin)
    n = crambin.n_atoms
    bad = {
        "not an archive": b"ATOM      1  N",
        "truncated": good[: len(good) // 2],
        "a coordinate at infinity": _repacked(good, positions=np.full((n, 3), np.inf)),
        "an index beyond the names": _repacked(
            good, atom_names_index=np.full(n, 10_000, dtype=np.int32)
        ),
        "a backbone atom beyond the atoms": _repacked(
            good, backbone_atoms=np.full(46, n, dtype=np.int64)
        ),
        "one b-factor short": _repacked(good, b_factors=np.zeros(n - 1)),
        "a missing array": _repacked(good, is_hetero=None),
    }
    for why, data in bad.items():
        with pytest.raises(StructureError) as info:
            unpack_structure(data, "1crn", "tcp://daemon:1crn", crambin.sha256)
        message = str(info.value)
        assert message.startswith("tcp://daemon:1crn: ") and "\n" not in message, (why, message)
