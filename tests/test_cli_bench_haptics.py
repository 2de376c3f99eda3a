"""`sasprobe bench haptics` runs end to end, and its stability cells classify correctly."""

from __future__ import annotations

import dataclasses
import json

from sasprobe.devices.base import PHANTOM_OMNI_LIMITS
from sasprobe.molecule import load_default

from sasprobe.cli.bench.haptics_stability import stability_cell
from tests.conftest import run_cli


def test_bench_haptics_quick_json(reference_entries, tmp_path):
    result = run_cli(
        "bench",
        "haptics",
        "--quick",
        "--json",
        "--structures",
        "1crn",
        "--ticks",
        "1500",
        "--repeats",
        "1",
        "--no-map",
        "--out",
        str(tmp_path),
        timeout=600,
    )
    assert result.returncode == 0, result.stderr
    data = json.loads(result.stdout)["benchmarks"]["haptics"]
    rows = {r["method"]: r for r in data["rows"]}
    assert set(rows) == {"proxy", "penalty"}
    for r in rows.values():
        assert r["n_atoms"] == 327 and r["ticks"] == 3000
        assert 0 < r["p50_us"] <= r["p99_us"] <= r["max_us"]
        assert r["contact_fraction"] > 0.1
    assert rows["proxy"]["max_penetration_A"] <= 1e-9
    assert (
        rows["penalty"]["max_penetration_A"] > 0.1
    )  # its surface point sits inside neighbours at creases
    assert rows["penalty"]["max_force_step_n"] > 2 * rows["proxy"]["max_force_step_n"]
    assert (tmp_path / "haptics_tick_time.png").stat().st_size > 0
    assert (tmp_path / "haptics_dive_force.png").stat().st_size > 0


def test_bench_haptics_rejects_unknown_structures(reference_entries):
    result = run_cli("bench", "haptics", "--structures", "9zzz")
    assert result.returncode == 2
    assert "unknown reference structure" in result.stderr and "Traceback" not in result.stderr


def test_stability_cells_follow_the_sampled_wall_passivity_bound():
    crambin = load_default()
    limits = dataclasses.replace(PHANTOM_OMNI_LIMITS, max_stiffness_n_per_mm=2.0)
    # K = 2 N/mm at 100 Hz is 9x past 2(b - B)/T = 0.22 N/mm: the held press buzzes
    loud = stability_cell(crambin, "proxy", 100, 2.0, limits)
    assert loud["unstable"] and loud["energy_mj"] > 10
    calm = stability_cell(crambin, "proxy", 1000, 0.3, limits)
    assert not calm["unstable"] and not calm["pop_through"] and calm["energy_mj"] < 0.5
    popped = stability_cell(crambin, "penalty", 1000, 0.3, limits)
    assert popped["pop_through"] and not calm["pop_through"]
