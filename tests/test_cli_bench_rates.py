"""`sasprobe bench rates` at its smallest: the simulated arm's row, quiet and beside a busy
loop, with sane figures, and the benchmark page's `rates` part written beside the others,
which it keeps."""

from __future__ import annotations

import json
import math

from sasprobe.cli.bench import rates, report
from tests.conftest import run_cli

OTHERS = {"all": "## All benchmarks\n\nanother run", "gpu-quick": "## GPU check\n\nanother machine"}


def test_a_row_quiet_and_a_row_beside_a_busy_loop_with_sane_figures():
    data = rates.measure(0.3, [2000.0], busy=1, devices={"simulated arm": None}, warmup_s=0.3)
    assert [(r["load"], r["rate_hz"]) for r in data["rows"]] == [
        ("quiet", 2000.0),
        ("busy", 2000.0),
    ]
    for row in data["rows"]:
        assert "error" not in row, row
        loop = row["loop"]
        assert loop["target_rate_hz"] == 2000.0 and loop["ticks"] > 0
        assert 0 <= loop["failed_reads"] <= loop["ticks"] and 0.0 <= rates.late_percent(loop) <= 100
        assert math.isfinite(loop["cpu_percent"]) and loop["period_error_us"]["p99"] is not None
    table = rates.markdown(data)
    assert table.count("| simulated arm | ") == 2 and "not run" not in table


def test_the_benchmark_writes_its_own_part_and_keeps_the_others(tmp_path):
    page = tmp_path / "benchmarks.md"
    for part, text in OTHERS.items():
        report.write_page(page, part, text)
    result = run_cli("bench", "rates", "--smoke", "--json", "--page", str(page), timeout=300)
    assert result.returncode == 0, result.stderr
    assert json.loads(result.stdout)["benchmarks"]["rates"]["rows"]
    text = page.read_text()
    assert all(other in text for other in OTHERS.values())
    part = text[
        text.index("<!-- sasprobe bench: rates -->") : text.index(
            "<!-- sasprobe bench: end rates -->"
        )
    ]
    assert f"## {report.PARTS['rates']}" in part and "| 0 | simulated arm | " in part
    assert (
        text.index("bench: all -->")
        < text.index("bench: rates -->")
        < text.index("bench: gpu-quick -->")
    )
