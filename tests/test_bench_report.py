"""`sasprobe bench --quick` assembles one report from several real benchmarks.

The whole quick run takes minutes (docs/benchmarks.md gives its wall time), so the test runs the
real `grid` and `sas` benchmarks on two small reference structures (a private MANIFEST)
and `haptics`, whose quick set needs structures that folder lacks: it must be listed as
skipped with its reason while the others still make the report.
"""

from __future__ import annotations

import json
import os
import re

from tests.conftest import run_cli

SMALL = ("1crn", "1oky")


def _small_data(reference_entries, folder):
    folder.mkdir()
    header = "id\tfile\tformat\tatoms\tprotein_heavy_atoms_or_note"
    rows = [header]
    for entry in reference_entries:
        if entry.id in SMALL:
            (folder / entry.path.name).symlink_to(entry.path)
            rows.append(f"{entry.id}\t{entry.path.name}\t{entry.format}\t{entry.atoms}\t{entry.note}")
    (folder / "MANIFEST.tsv").write_text("\n".join(rows) + "\n")
    return folder


def test_quick_report_joins_benchmarks_machine_and_charts(reference_entries, tmp_path):
    data = _small_data(reference_entries, tmp_path / "pdb")
    out = tmp_path / "report"
    result = run_cli("bench", "--quick", "--only", "grid,sas,haptics", "--out", str(out),
                     env=dict(os.environ, SASPROBE_DATA=str(data)), timeout=300)
    assert result.returncode == 0, result.stderr
    assert "bench haptics skipped" in result.stderr
    report = (out / "report.md").read_text()
    summary = json.loads((out / "report.json").read_text())
    assert summary["quick"] is True and set(summary["benchmarks"]) == {"grid", "sas"}
    assert "unknown reference structure" in summary["skipped"]["haptics"]
    # The machine: CPU, cores and the GL renderer string (Mesa's llvmpipe here, a GPU elsewhere).
    machine = summary["machine"]
    assert machine["cpu"] and machine["cores"] >= 1 and machine["gl_renderer"]
    assert f"| cpu | {machine['cpu']} |" in report and f"| gl_renderer | {machine['gl_renderer']} |" in report
    # One section per benchmark that ran, its wall time, and every chart it drew beside the report.
    for name in ("grid", "sas"):
        per_benchmark = json.loads((out / f"{name}.json").read_text())
        assert {s["id"] for s in per_benchmark["structures"]} == set(SMALL)
        assert re.search(rf"\| {name} \| \d+\.\d \|", report)
    assert re.search(r"\| haptics \| skipped: .*unknown reference structure", report)
    charts = re.findall(r"!\[[^\]]*\]\(([^)]+)\)", report)
    assert set(charts) == {"grid_build.png", "sas_speed_accuracy.png"}
    for chart in charts:
        assert (out / chart).read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert report.index("## Structure loading") < report.index("## Solvent accessible")


def test_unknown_benchmark_name_is_one_line():
    result = run_cli("bench", "--only", "grid,nonsense")
    lines = result.stderr.strip().splitlines()
    assert result.returncode == 2 and len(lines) == 1 and "unknown benchmark(s) nonsense" in lines[0]
