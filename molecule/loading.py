"""Loading a macromolecular structure (PDB or mmCIF, plain or gzipped) through gemmi into a
Structure (molecule/structure.py).

Rules (the same for every command, so what is felt and what is drawn agree):
- the first model only;
- alternate locations: per residue, the conformer with the highest occupancy is kept
  (ties: the one that appears first); atoms without an altloc are always kept;
- waters are removed unless `keep_water`;
- hydrogens, ligands and ions are kept.

Every problem a user can cause (missing, empty, garbage, truncated file, nothing left
after filtering) raises StructureError with one line naming the file. What is read is
bounded before it can hurt: only regular files are opened (a FIFO, device or folder is
refused before any read), gzip is inflated to at most `inflate_limit()` bytes (a
gzip bomb stops there), a PDB file's coordinates must be numbers (molecule/pdb_text.py),
and every coordinate must be finite and within ±MAX_COORDINATE_A Å (the uniform grid
indexes cells from them).
"""

from __future__ import annotations

import hashlib
import logging
import zlib
from importlib import resources
from pathlib import Path

import gemmi
import numpy as np
from sasprobe.molecule.backbone import trace_segments
from sasprobe.molecule.elements import FALLBACK_RADIUS, colors_for, has_bondi_radius, radii_for
from sasprobe.molecule.pdb_text import bad_coordinate, truncation
from sasprobe.molecule.structure import (
    DEFAULT_STRUCTURE,
    MAX_COORDINATE_A,
    Structure,
    StructureError,
    structure_name,
)

from sasprobe.common.files import read_regular

log = logging.getLogger("sasprobe")

MAX_FILE_BYTES = 1 << 30  # a structure file (gzipped or not) larger than this is not read
INFLATE_RATIO = 32  # gzip: structures inflate 4-6x (the shared entries); a bomb inflates ~1000x
INFLATE_FLOOR = 64 << 20  # ... but a small file may always inflate to this
INFLATE_CEILING = 2 << 30  # ... and nothing beyond this
_INFLATE_CHUNK = 1 << 20


def load_structure(path: str | Path, keep_water: bool = False) -> Structure:
    """Load a PDB or mmCIF file (optionally .gz); raises StructureError on bad input."""
    path = Path(path)
    return parse_structure(
        read_regular_file(path, MAX_FILE_BYTES),
        name=structure_name(path.name),
        source=str(path),
        keep_water=keep_water,
    )


def read_regular_file(path: str | Path, limit: int) -> bytes:
    """A structure file's bytes: a regular file of at most `limit` bytes, else StructureError."""
    return read_regular(path, limit, "structure file", StructureError)


def load_default(keep_water: bool = False) -> Structure:
    """The embedded default structure (crambin, 1CRN)."""
    data = resources.files("sasprobe.molecule").joinpath("data", DEFAULT_STRUCTURE).read_bytes()
    return parse_structure(
        data,
        name=structure_name(DEFAULT_STRUCTURE),
        source=f"embedded:{DEFAULT_STRUCTURE}",
        keep_water=keep_water,
    )


def load_structure_or_default(
    path: str | Path | None, keep_water: bool = False, fetch=None
) -> Structure:
    """The embedded default (None), a file, or a PDB id (`4hhb`, `pdb:4hhb`: molecule/fetch.py,
    with `fetch`'s FetchSettings or the environment's)."""
    if path is None:
        return load_default(keep_water)
    from sasprobe.molecule.fetch import resolve

    return load_structure(resolve(str(path), fetch), keep_water)


def parse_structure(data: bytes, name: str, source: str, keep_water: bool = False) -> Structure:
    """Parse structure file bytes (gzip detected from the magic number, format from content)."""
    if not data:
        raise StructureError(f"{source}: file is empty")
    text = _decompress(data, source)
    if not text.strip():
        raise StructureError(f"{source}: file is empty")
    if b"\x00" in text[:65536]:
        raise StructureError(f"{source}: not a PDB or mmCIF text file (binary content)")
    is_cif = _looks_like_cif(text)
    problem = None if is_cif else truncation(text) or bad_coordinate(text)
    if problem is not None:
        raise StructureError(f"{source}: {problem}")
    try:
        fmt = gemmi.CoorFormat.Mmcif if is_cif else gemmi.CoorFormat.Pdb
        st = gemmi.read_structure_string(text, format=fmt)
    except (RuntimeError, ValueError, IndexError) as exc:
        reason = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
        reason = reason.replace("string:", "line ", 1)
        raise StructureError(f"{source}: cannot parse ({_shorten(reason)})") from None
    if len(st) == 0 or st[0].count_atom_sites() == 0:
        raise StructureError(f"{source}: no atoms found (not a PDB or mmCIF structure?)")
    while len(st) > 1:  # first model only
        del st[len(st) - 1]
    if not keep_water:
        st.remove_waters()
    st.remove_empty_chains()
    if st[0].count_atom_sites() == 0:
        hint = "" if keep_water else " after removing waters (use --keep-water to keep them)"
        raise StructureError(f"{source}: no atoms left{hint}")
    return _to_arrays(st[0], data, name, source)


def _to_arrays(model: gemmi.Model, data: bytes, name: str, source: str) -> Structure:
    xyz: list[tuple[float, float, float]] = []
    occupancy: list[float] = []
    b_iso: list[float] = []
    altloc: list[str] = []
    elements: list[str] = []
    atom_names: list[str] = []
    residue_of_atom: list[int] = []
    chains: list[str] = []
    res_names: list[str] = []
    res_nums: list[int] = []
    icodes: list[str] = []
    hetero: list[bool] = []
    try:  # gemmi gives names as UTF-8: a mangled byte fails only when one is read
        for chain in model:
            for residue in chain:
                if residue.seqid.num is None:  # a blank or garbled number (PDB columns 23-26)
                    raise StructureError(
                        f"{source}: residue {residue.name} of chain {chain.name} "
                        "has no sequence number"
                    )
                chains.append(chain.name)
                res_names.append(residue.name)
                res_nums.append(residue.seqid.num)
                icodes.append(residue.seqid.icode.strip())
                hetero.append(residue.het_flag == "H")
                r = len(res_names) - 1
                for atom in residue:
                    p = atom.pos
                    xyz.append((p.x, p.y, p.z))
                    occupancy.append(atom.occ)
                    b_iso.append(atom.b_iso)
                    altloc.append(atom.altloc)
                    elements.append(atom.element.name)
                    atom_names.append(atom.name)
                    residue_of_atom.append(r)
    except UnicodeDecodeError as exc:
        raise StructureError(
            f"{source}: a chain, residue or atom name is not UTF-8 text "
            f"(byte 0x{exc.object[exc.start]:02x})"
        ) from None
    res_index = np.asarray(residue_of_atom, dtype=np.int64)
    keep = _choose_conformers(
        np.asarray(chains)[res_index],
        np.asarray(res_nums, dtype=np.int64)[res_index],
        np.asarray(icodes)[res_index],
        np.asarray(altloc),
        np.asarray(occupancy, dtype=np.float64),
    )
    res_index = res_index[keep]
    positions = np.asarray(xyz, dtype=np.float64).reshape(-1, 3)[keep]
    _check_coordinates(
        positions, np.asarray(atom_names)[keep], res_index, chains, res_names, res_nums, source
    )
    element_arr = np.asarray(elements)[keep]
    warnings: list[str] = []
    unknown = int(np.count_nonzero(element_arr == "X"))
    if unknown:
        warnings.append(
            f"{source}: element of {unknown} atom(s) could not be determined; "
            f"using the fallback radius {FALLBACK_RADIUS:.2f} Å"
        )
    lacking = sorted({e for e in np.unique(element_arr) if e != "X" and not has_bondi_radius(e)})
    if lacking:
        log.info(
            "%s: no Bondi radius for %s; using %.2f Å", source, ", ".join(lacking), FALLBACK_RADIUS
        )
    for message in warnings:
        log.warning(message)
    structure = Structure(
        name=name,
        source=source,
        source_bytes=data,
        sha256=hashlib.sha256(data).hexdigest(),
        positions=positions,
        elements=element_arr,
        vdw_radii=radii_for(element_arr),
        colors=colors_for(element_arr),
        chain_ids=np.asarray(chains)[res_index],
        residue_names=np.asarray(res_names)[res_index],
        residue_numbers=np.asarray(res_nums, dtype=np.int32)[res_index],
        insertion_codes=np.asarray(icodes)[res_index],
        atom_names=np.asarray(atom_names)[keep],
        is_hetero=np.asarray(hetero, dtype=bool)[res_index],
        b_factors=np.asarray(b_iso, dtype=np.float64)[keep],
        backbone=[],
        backbone_chains=[],
        warnings=warnings,
    )
    structure.backbone, structure.backbone_chains = trace_segments(structure)
    return structure


def _check_coordinates(
    positions: np.ndarray, atom_names, res_index, chains, res_names, res_nums, source: str
) -> None:
    """Finite and within ±MAX_COORDINATE_A, or StructureError naming the first bad atom."""
    finite = np.isfinite(positions).all(axis=1)
    inside = finite.copy()
    inside[finite] = (np.abs(positions[finite]) <= MAX_COORDINATE_A).all(axis=1)
    if inside.all():
        return
    if not finite.all():
        bad, why = np.flatnonzero(~finite), "non-finite coordinates (NaN or infinite)"
    else:
        bad, why = np.flatnonzero(~inside), f"coordinates beyond ±{MAX_COORDINATE_A:g} Å"
    first = int(bad[0])
    r = int(res_index[first])
    raise StructureError(
        f"{source}: {bad.size} atom(s) with {why}; first: atom {atom_names[first]} of "
        f"{res_names[r]} {res_nums[r]} chain {chains[r]}"
    )


def _choose_conformers(
    chains: np.ndarray,
    numbers: np.ndarray,
    icodes: np.ndarray,
    altloc: np.ndarray,
    occupancy: np.ndarray,
) -> np.ndarray:
    """Mask of atoms to keep: per residue the altloc with the highest occupancy, ties -> first.

    Residues are grouped by (chain, number, insertion code) so that microheterogeneity
    (two residue names at one position) is resolved the same way.
    """
    keep = np.ones(altloc.shape[0], dtype=bool)
    alt_atoms = np.flatnonzero(altloc != "\x00")
    if alt_atoms.size == 0:
        return keep
    # Only atoms with an altloc reach this loop: a few dozen in a typical entry.
    # (residue key) -> {letter: (max occupancy, first appearance)}
    conformers: dict[tuple, dict[str, tuple[float, int]]] = {}
    for order, i in enumerate(alt_atoms):
        letters = conformers.setdefault((chains[i], int(numbers[i]), icodes[i]), {})
        occ, first = letters.get(altloc[i], (-np.inf, order))
        letters[altloc[i]] = (max(occ, float(occupancy[i])), first)
    chosen = {
        key: max(letters.items(), key=lambda item: (item[1][0], -item[1][1]))[0]
        for key, letters in conformers.items()
    }
    for i in alt_atoms:
        keep[i] = altloc[i] == chosen[(chains[i], int(numbers[i]), icodes[i])]
    return keep


def inflate_limit(compressed_bytes: int) -> int:
    """How far gzip data of this size may inflate: INFLATE_RATIO times, within floor and ceiling."""
    return min(max(INFLATE_RATIO * compressed_bytes, INFLATE_FLOOR), INFLATE_CEILING)


def _decompress(data: bytes, source: str) -> bytes:
    """gzip (every member, as gzip.decompress does) inflated in bounded steps; plain data as is."""
    if bytes(data[:2]) != b"\x1f\x8b":
        return bytes(data)
    limit = inflate_limit(len(data))
    out: list[bytes] = []
    total = 0
    rest = memoryview(data)
    try:
        while rest.nbytes:
            inflater = zlib.decompressobj(16 + zlib.MAX_WBITS)
            pending = rest
            while True:
                chunk = inflater.decompress(pending, min(_INFLATE_CHUNK, limit - total + 1))
                total += len(chunk)
                out.append(chunk)
                if total > limit:
                    raise StructureError(
                        f"{source}: gzip data inflates beyond {limit >> 20} MiB "
                        f"({INFLATE_RATIO}x its {len(data)} bytes; a gzip bomb?)"
                    )
                if inflater.eof:
                    break
                pending = inflater.unconsumed_tail
                if not pending and not chunk:
                    raise StructureError(
                        f"{source}: corrupt or truncated gzip data (ends inside a member)"
                    )
            rest = memoryview(inflater.unused_data)
            if rest.nbytes and bytes(rest[:2]) != b"\x1f\x8b":
                break  # trailing garbage after the last member, as gzip tolerates padding
    except zlib.error as exc:
        raise StructureError(f"{source}: corrupt or truncated gzip data ({exc})") from None
    return b"".join(out)


def _looks_like_cif(text: bytes) -> bool:
    for line in text[:65536].splitlines():
        stripped = line.strip()
        if not stripped or stripped.startswith(b"#"):
            continue
        return stripped.startswith(b"data_")
    return False


def _shorten(text: str, limit: int = 160) -> str:
    return text if len(text) <= limit else text[: limit - 3] + "..."
