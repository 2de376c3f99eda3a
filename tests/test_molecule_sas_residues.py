"""`sasprobe sas --per-residue` (table, CSV, JSON) through the real CLI: each residue's row
is the sum of its atoms' rows in the per-atom CSV, and every atom is in exactly one residue."""

from __future__ import annotations

import csv
import io
import json
from collections import defaultdict

from tests.conftest import run_cli


def test_per_residue_rows_sum_the_atoms():
    atoms = list(csv.DictReader(io.StringIO(run_cli("sas", "--csv").stdout)))
    residues = list(csv.DictReader(io.StringIO(run_cli("sas", "--per-residue", "--csv").stdout)))
    assert len(atoms) == 327 and len(residues) == 46  # 1CRN
    sums, counts, accessible = defaultdict(float), defaultdict(int), defaultdict(int)
    for a in atoms:
        key = (a["chain"], a["number"], a["icode"], a["residue"])
        sums[key] += float(a["area"])
        counts[key] += 1
        accessible[key] += a["accessible"] == "True"
    assert [(r["chain"], r["number"], r["icode"], r["residue"]) for r in residues] == list(sums)
    for r in residues:
        key = (r["chain"], r["number"], r["icode"], r["residue"])
        assert int(r["atoms"]) == counts[key] and int(r["accessible_atoms"]) == accessible[key]
        assert abs(float(r["area"]) - sums[key]) < 1e-3 * counts[key]
    table = run_cli("sas", "--per-residue").stdout.splitlines()
    assert any(line.split()[:3] == ["A", "1", "THR"] for line in table), table[:5]
    data = json.loads(run_cli("sas", "--per-residue", "--json").stdout)
    assert data["residues"]["residue"][:3] == ["THR", "THR", "CYS"]
    assert abs(sum(data["residues"]["area"]) - data["total_area"]) < 0.01
    both = run_cli("sas", "--csv", "--json")
    assert both.returncode == 2 and len(both.stderr.strip().splitlines()) == 1
