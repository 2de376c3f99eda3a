"""The scenario benchmarks and the GPU check run end to end at tiny sizes: `sasprobe bench
render --scenarios-only` prints the three scenarios with their ratios (and PyMOL's where
pymol-open-source is installed), and the GPU check's code path runs on llvmpipe."""

from __future__ import annotations

import json
import os
import re

import pytest

from sasprobe.cli.bench import gpu_quick, render_pymol
from tests.conftest import run_cli
from tests.support.reference_data import small_reference_data

# each test runs a benchmark whole: minutes on a busy machine
pytestmark = [pytest.mark.needs_gl(430), pytest.mark.timeout(600)]


def test_render_scenarios_print_every_case_with_its_ratios(reference_entries, tmp_path):
    data = small_reference_data(reference_entries, tmp_path / "pdb")  # 1CRN and 1OKY
    out = tmp_path / "report"
    r = run_cli(
        "bench",
        "render",
        "--quick",
        "--scenarios-only",
        "--scenario-size",
        "64x48",
        "--out",
        str(out),
        env=dict(os.environ, SASPROBE_DATA=str(data)),
        timeout=300,
    )
    assert r.returncode == 0, r.stderr
    report = (out / "report.md").read_text()
    scenarios = json.loads((out / "render.json").read_text())["scenarios"]
    for key, title in (
        ("session", "(a) haptic session"),
        ("orbit", "(b) orbit"),
        ("cube", "(c) cube drifting"),
    ):
        rows = scenarios[key][0]["rows"]
        assert rows["unlit"]["over_unlit"] == 1.0 and rows["full redraw"]["full_over_this"] == 1.0
        for label, row in rows.items():
            assert row["ms"] > 0 and row["frames"] == scenarios["frames"]
            assert re.search(
                rf"\| {re.escape(title)} \| \w+ \| {re.escape(label)} "
                r"\| [\d.]+ \| [\d.]+ \| [\d.]+ \|",
                report,
            ), (title, label)
    session = scenarios["session"][0]["rows"]["session (frame cache)"]
    assert session["cache_hits"] >= scenarios["frames"]  # the camera stood still: the layer held
    assert scenarios["orbit"][0]["rows"]["frame cache"]["cache_hits"] == 0  # it turned every frame
    assert scenarios["session"][0]["contact_fraction"] >= 0.5  # the demo path touches the surface
    assert len(scenarios["load"]) == 2 and "load average" in report
    if render_pymol.pymol_available():
        assert "ray_shadows 1" in report and "× |" in report.split("PyMOL")[-1]
    else:
        assert "pymol-open-source is not installed" in report


def test_gpu_check_runs_here_at_a_small_size(reference_by_id, gl):
    """The check's code path, shortened: 1CRN whole and 1OKY with a ~300-atom cube (the full
    check: 1CRN, 1TII, 1AON whole, 6ZU5 with a cube, at 1920x1080)."""
    try:
        result = gpu_quick.run(
            size=(64, 36), frames=3, structures=("1crn", "1oky"), cube_id="1oky", first_frames=False
        )
    finally:
        # The check makes a context of its own and releases it, which leaves none current:
        # the session's is made current again, or every later test's GL calls would fail.
        gl.__enter__()
    text = gpu_quick.markdown(result, None)
    assert [r["id"] for r in result["rows"]] == ["1crn", "1oky"]
    for row in result["rows"]:
        assert set(row["cases"]) == {"unlit", "default lighting, whole", "session frame"}
        assert all(c["ms"] > 0 for c in row["cases"].values())
    assert 250 <= result["rows"][1]["cube_atoms"] <= 400 and "1oky + " in text
    assert [b["id"] for b in result["bakes"]] == ["1oky cube"] and result["bakes"][0][
        "patches"
    ] >= 250
    assert "| 1crn whole | 327 |" in text
    assert [(r["id"], r["lighting"]) for r in result["sessions"]["rows"]] == [
        ("1crn", "unlit"),
        ("1crn", "lit"),
        ("1oky", "unlit"),
        ("1oky", "lit"),
    ] and "Session frames" in text


def test_the_sessions_table_compares_each_structure_with_the_first_in_every_round(
    reference_by_id, gl
):
    """bench/render_sessions.py at a tiny size, two rounds: every structure's rows unlit and
    lit, ratios to the first structure 1 for itself, kept layers counted, the first frame timed
    in process and through `render --connect --frames 1` against a daemon it starts."""
    from sasprobe.cli.bench import render_sessions

    d = render_sessions.run_sessions(
        gl, reference_by_id, sizes=((64, 36),), structures=("1crn", "1oky"), frames=4, rounds=2
    )
    rows = {(r["id"], r["lighting"]): r for r in d["rows"]}
    assert set(rows) == {(sid, lit) for sid in ("1crn", "1oky") for lit in ("unlit", "lit")}
    for (sid, _), r in rows.items():
        assert r["cpu_ms"] > 0 and r["ms"] > 0 and 0 <= r["kept"] <= 4 and r["first_frame_s"] > 0
        assert 0 < r["connect_frames_1_s"] < 120, r  # the subprocess drew its frame and ended
        lo, hi = r["over_1crn_cpu_range"]
        assert lo <= r["over_1crn_cpu"] <= hi
        if sid == "1crn":
            assert r["over_1crn_cpu"] == r["over_1crn"] == 1.0
    assert rows["1oky", "lit"]["lit_over_unlit_cpu"] > 0
    text = render_sessions.markdown(d)
    assert "| 1oky | " in text and "`--frames 1`" in text


def test_gpu_check_runs_alone():
    r = run_cli("bench", "--gpu-quick", "--only", "grid")
    lines = r.stderr.strip().splitlines()
    assert r.returncode == 2 and len(lines) == 1 and "--gpu-quick runs on its own" in lines[0]
