"""`sasprobe info` through the real CLI: JSON fields and every bad-input case."""

from __future__ import annotations

import gzip
import json

import pytest

from tests.conftest import run_cli

INFO_FIELDS = {
    "n_atoms",
    "n_chains",
    "n_residues",
    "bbox_min",
    "bbox_max",
    "backbone_segments",
    "load_seconds",
    "grid_seconds",
    "grid",
}
GRID_FIELDS = {
    "cell_size",
    "dims",
    "n_cells",
    "n_nonempty",
    "max_per_cell",
    "mean_per_nonempty",
    "bytes",
}


def test_info_default_human_and_json():
    human = run_cli("info")
    assert human.returncode == 0, human.stderr
    assert "1crn" in human.stdout and "327" in human.stdout
    out = run_cli("info", "--json", "--probe-radius", "1.2", "--cell-size", "5")
    data = json.loads(out.stdout)
    assert INFO_FIELDS <= data.keys() and GRID_FIELDS <= data["grid"].keys()
    assert (
        data["n_atoms"] == 327 and data["grid"]["cell_size"] == 5.0 and data["probe_radius"] == 1.2
    )


def test_info_json_on_every_shared_structure(reference_entries):
    for entry in reference_entries:
        out = run_cli("info", str(entry.path), "--json")
        assert out.returncode == 0, (entry.id, out.stderr)
        data = json.loads(out.stdout)
        assert INFO_FIELDS <= data.keys() and GRID_FIELDS <= data["grid"].keys()
        assert data["n_atoms"] > 0 and data["grid"]["n_nonempty"] > 0


def _assert_one_line_error(result, *needles):
    assert result.returncode == 2, result.stderr
    assert "Traceback" not in result.stderr
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1, result.stderr
    for needle in needles:
        assert needle in lines[0], lines[0]
    assert result.stdout == ""


@pytest.fixture(scope="module")
def bad_files(tmp_path_factory, reference_by_id):
    d = tmp_path_factory.mktemp("bad")
    pdb = gzip.decompress(reference_by_id["1crn"].path.read_bytes())
    cif = gzip.decompress(reference_by_id["6zu5"].path.read_bytes())
    files = {
        "empty": (b"", "empty"),
        "garbage_binary": (bytes(range(256)) * 20, "not a PDB or mmCIF"),
        "garbage_text": (b"hello, this is not a structure\n" * 50, "no atoms"),
        "truncated_midline": (pdb[: pdb.index(b"ATOM    100") + 40], "truncated"),
        "truncated_at_line": (pdb[: pdb.index(b"ATOM    200")], "truncated"),
        "truncated_gzip": (gzip.compress(pdb)[:3000], "truncated gzip"),
        "truncated_cif": (cif[: len(cif) // 3], "cannot parse"),
        "only_water": (
            b"".join(
                (
                    f"HETATM{i + 1:5d}  O   HOH W{i + 1:4d}    {i * 3.0:8.3f}{0.0:8.3f}{0.0:8.3f}"
                    "  1.00 10.00           O\n"
                ).encode()
                for i in range(10)
            ),
            "no atoms left",
        ),
    }
    paths = {}
    for name, (data, needle) in files.items():
        suffix = ".cif" if "cif" in name else ".pdb.gz" if "gzip" in name else ".pdb"
        p = d / f"{name}{suffix}"
        p.write_bytes(data)
        paths[name] = (p, needle)
    return paths


@pytest.mark.parametrize(
    "case",
    [
        "empty",
        "garbage_binary",
        "garbage_text",
        "truncated_midline",
        "truncated_at_line",
        "truncated_gzip",
        "truncated_cif",
        "only_water",
    ],
)
def test_bad_structure_files_give_one_clear_line(bad_files, case):
    path, needle = bad_files[case]
    _assert_one_line_error(run_cli("info", str(path)), str(path), needle)


def test_missing_file_and_directory(tmp_path):
    missing = tmp_path / "nope.pdb"
    _assert_one_line_error(run_cli("info", str(missing)), str(missing), "no such file")
    _assert_one_line_error(run_cli("info", str(tmp_path)), str(tmp_path), "directory")


def test_only_water_can_be_kept(bad_files):
    path, _ = bad_files["only_water"]
    out = run_cli("info", str(path), "--keep-water", "--json")
    assert out.returncode == 0 and json.loads(out.stdout)["n_atoms"] > 0


@pytest.mark.parametrize(
    "args",
    [
        ["--probe-radius", "0"],
        ["--probe-radius", "-1"],
        ["--probe-radius", "nan"],
        ["--probe-radius", "50"],
        ["--cell-size", "abc"],
        ["--bogus"],
    ],
)
def test_bad_options_give_one_clear_line(args):
    _assert_one_line_error(run_cli("info", *args))


def test_unknown_element_warns_once(tmp_path):
    lines = "".join(
        f"ATOM  {i + 1:5d}  QQ  UNK A   1    {i * 3.0:8.3f}{0.0:8.3f}{0.0:8.3f}  1.00 10.00\n"
        for i in range(5)
    )
    p = tmp_path / "odd.pdb"
    p.write_text(lines)
    out = run_cli("info", str(p), "--json")
    assert out.returncode == 0
    warnings = [line for line in out.stderr.splitlines() if "warning" in line]
    assert len(warnings) == 1 and "odd.pdb" in warnings[0] and "1.80" in warnings[0]
