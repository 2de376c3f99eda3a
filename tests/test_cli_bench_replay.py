"""`sasprobe bench replay --smoke`: every way of reading a recording runs on two short
sessions and reports sane figures, and the run writes its own part of the benchmark page,
keeping the others."""

from __future__ import annotations

import json
import math

import pytest

from sasprobe.cli.bench import report
from sasprobe.cli.bench.replay import MODES
from tests.conftest import run_cli

OTHER_PART = "## All benchmarks\n\nfigures of another run"


@pytest.fixture(scope="module")
def smoke(gl, tmp_path_factory):
    folder = tmp_path_factory.mktemp("replay")
    page = folder / "docs" / "benchmarks.md"
    report.write_page(page, "all", OTHER_PART)
    result = run_cli("bench", "replay", "--smoke", "--json", "--page", str(page), timeout=900)
    assert result.returncode == 0, result.stderr
    return json.loads(result.stdout)["benchmarks"]["replay"], page


def test_every_mode_reads_both_recordings(smoke):
    figures, _ = smoke
    assert figures["modes"] == list(MODES)
    assert len(figures["recordings"]) == 2
    for recording in figures["recordings"]:
        assert recording["format"] == 2 and recording["ticks"] > 0 and recording["megabytes"] > 0
        for mode in MODES:
            run = recording["modes"][mode]
            assert run["wall_s"] > 0 and run["peak_rss_mb"] > 20, (mode, run)
            assert math.isfinite(run["ticks_per_s"]) and run["ticks_per_s"] > 0
        assert recording["modes"]["verify"]["ok"]
        assert recording["modes"]["device"]["ticks"] == recording["ticks"] + 1  # and the end
    assert set(figures["peak_ratio_longest_to_shortest"]) == set(MODES)
    assert figures["recorder"]["dropped"] == 0 and figures["recorder"]["ticks_per_s"] > 0


def test_the_run_writes_its_own_part_of_the_page(smoke):
    _, page = smoke
    text = page.read_text()
    assert OTHER_PART in text
    part = text[
        text.index("<!-- sasprobe bench: replay -->") : text.index(
            "<!-- sasprobe bench: end replay -->"
        )
    ]
    assert "## Long recordings" in part and "| recording | ticks |" in part
    assert "(benchmarks/replay_memory.png)" in part
    assert (page.parent / "benchmarks" / "replay_memory.png").read_bytes()[:4] == b"\x89PNG"
