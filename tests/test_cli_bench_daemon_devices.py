"""`sasprobe bench daemon`'s rows on the emulated Force Dimension omega.3 and Haply Inverse3, at
their smallest size: each starts its emulator (a C library built here, a WebSocket service)
and a daemon on it, and reports sane figures. `sasprobe bench --smoke` runs one emulated
device only, so these rows are run here."""

from __future__ import annotations

import math
import shutil

from sasprobe.cli.bench import daemon_devices
from tests.conftest import skip_or_fail

ROWS = {
    "Force Dimension omega.3 (stand-in libdhd)": "omega.3",
    "Haply Inverse3 (stand-in Inverse Service)": "Haply Inverse3",
}


def _numbers(tree):
    if isinstance(tree, dict):
        for value in tree.values():
            yield from _numbers(value)
    elif isinstance(tree, (int, float)) and not isinstance(tree, bool):
        yield tree


def test_the_omega3_and_inverse3_rows_run_with_sane_figures():
    if shutil.which("cc") is None and shutil.which("gcc") is None:
        skip_or_fail("no C compiler to build the stand-in DHD library")
    data = daemon_devices.measure(0.5, labels=list(ROWS))
    assert [row["label"] for row in data["rows"]] == list(ROWS)
    for row in data["rows"]:
        assert "error" not in row, row
        assert row["device"] == ROWS[row["label"]]
        assert all(math.isfinite(v) for v in _numbers(row)), row
        loop, reads = row["loop"], row["reads"]
        assert loop["rate_hz"] > 0 and loop["ticks"] > 0
        assert reads["ticks"] > 0 and 0 <= reads["failed"] <= reads["ticks"]
        assert 0 < reads["p50_us"] <= reads["p99_us"] <= reads["max_us"]
    # without --rate each runs at the rate its driver declares: 1 kHz
    targets = {row["device"]: row["loop"]["target_rate_hz"] for row in data["rows"]}
    assert targets == {"omega.3": 1000.0, "Haply Inverse3": 1000.0}
    table = daemon_devices.markdown(data)
    assert all(label in table for label in ROWS) and "not run" not in table
