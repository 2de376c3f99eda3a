"""Structure files mangled by the thousand: 1CRN as PDB and as mmCIF, cut, with bytes
flipped or inserted, lines dropped, repeated or swapped, coordinate and record fields
garbled, gzipped or not. Each one loads or is refused in one line, through the loader and
through `sasprobe info` (in this process, so a traceback is this test's failure), never an
exception of another kind. tests/support/fuzz.py says how many."""

from __future__ import annotations

import gzip
import io
import json
import logging
from contextlib import redirect_stderr, redirect_stdout

import gemmi
import pytest
from hypothesis import given
from hypothesis import strategies as st
from sasprobe.molecule import parse_structure

from sasprobe.cli.main import main
from sasprobe.common.errors import UserError
from tests.support.fuzz import Seeds, cli_error_lines, fuzz_settings, one_line_error

GARBLE = [b"", b" ", b"nan", b"-inf", b"1e999", b"-99999999", b"*****", b"\xff\xfe", b"\t", b"A"]


@pytest.fixture(scope="module")
def seeds(reference_by_id):
    pdb = gzip.decompress(reference_by_id["1crn"].path.read_bytes())
    document = gemmi.read_structure_string(pdb.decode()).make_mmcif_document()
    return Seeds([pdb, document.as_string().encode()])


@pytest.fixture(scope="module")
def folder(tmp_path_factory):
    return tmp_path_factory.mktemp("mangled")


@pytest.fixture
def cli_logging_restored():
    """main() sets up the sasprobe logger for a command line; the other tests' logging is left
    as it was."""
    logger = logging.getLogger("sasprobe")
    saved = logger.handlers[:], logger.level, logger.propagate
    yield
    logger.handlers[:], logger.level, logger.propagate = saved


def mangle(data: bytes, draw) -> bytes:
    """Up to eight edits of the kinds a damaged download or a careless hand makes."""
    for _ in range(draw(st.integers(1, 8))):
        lines = data.split(b"\n")
        kind = draw(st.sampled_from(["cut", "flip", "insert", "line", "field", "splice"]))
        at = draw(st.integers(0, max(len(data) - 1, 0)))
        if kind == "cut":
            data = data[:at]
        elif kind == "flip" and data:
            data = data[:at] + bytes([data[at] ^ draw(st.integers(1, 255))]) + data[at + 1 :]
        elif kind == "insert":
            data = data[:at] + draw(st.binary(max_size=16)) + data[at:]
        elif kind == "line" and lines:
            i, j = (draw(st.integers(0, len(lines) - 1)) for _ in range(2))
            how = draw(st.sampled_from(["drop", "repeat", "swap"]))
            if how == "drop":
                del lines[i]
            elif how == "repeat":
                lines.insert(i, lines[i])
            else:
                lines[i], lines[j] = lines[j], lines[i]
            data = b"\n".join(lines)
        elif kind == "field" and lines:  # a PDB column range, or an mmCIF token, garbled
            i = draw(st.integers(0, len(lines) - 1))
            start = draw(st.integers(0, 80))
            end = start + draw(st.integers(0, 12))
            line = lines[i]
            lines[i] = line[:start] + draw(st.sampled_from(GARBLE)) + line[end:]
            data = b"\n".join(lines)
        elif kind == "splice":
            data = data[:at] + data[draw(st.integers(0, max(len(data) - 1, 0))) :]
    return gzip.compress(data, 1) if draw(st.booleans()) else data


def _first_atom_with(pdb: bytes, columns: slice, text: bytes) -> bytes:
    """The first ATOM record with `columns` (0-based) overwritten by `text`."""
    lines = pdb.split(b"\n")
    i = next(i for i, line in enumerate(lines) if line.startswith(b"ATOM"))
    lines[i] = lines[i][: columns.start] + text + lines[i][columns.stop :]
    return b"\n".join(lines)


@pytest.mark.parametrize(
    ("columns", "text", "error"),
    [  # found by the fuzz below: a TypeError, then a UnicodeDecodeError
        (slice(22, 26), b"    ", "residue THR of chain A has no sequence number"),
        (slice(17, 20), b"T\x80R", "a chain, residue or atom name is not UTF-8 text (byte 0x80)"),
    ],
)
def test_a_damaged_atom_record_is_refused_in_one_line(seeds, columns, text, error):
    with pytest.raises(UserError) as refused:
        parse_structure(_first_atom_with(seeds[0], columns, text), "mangled", "mangled.pdb")
    assert one_line_error(refused.value) == f"mangled.pdb: {error}"


@fuzz_settings(200)
@given(data=st.data())
def test_a_mangled_structure_loads_or_is_refused_in_one_line(seeds, data):
    text = mangle(seeds[data.draw(st.integers(0, 1))], data.draw)
    try:
        structure = parse_structure(text, "mangled", "mangled.pdb")
    except UserError as exc:
        one_line_error(exc)
    else:
        assert structure.n_atoms > 0


@fuzz_settings(100)
@given(data=st.data())
def test_sasprobe_info_on_a_mangled_structure_answers_or_says_why_in_one_line(
    seeds, folder, cli_logging_restored, data
):
    seed = data.draw(st.integers(0, 1))
    path = folder / ("mangled.pdb", "mangled.cif")[seed]
    path.write_bytes(mangle(seeds[seed], data.draw))
    out, err = io.StringIO(), io.StringIO()
    with redirect_stdout(out), redirect_stderr(err):
        status = main(["info", str(path), "--json"])
    assert status in (0, 2)
    cli_error_lines(err.getvalue(), failed=status == 2)
    if status == 0:
        assert json.loads(out.getvalue())["n_atoms"] > 0
