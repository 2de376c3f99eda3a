"""Faults the simulated arm cannot produce on its own: slow reads and driver exceptions.

The daemon runs in this process (real sockets, real loop) on the simulated arm with
two extra failure modes layered on top.
"""

from __future__ import annotations

import time

import numpy as np
from sasprobe.daemon.service import Daemon, DaemonConfig
from sasprobe.devices.registry import SCHEMES, DeviceScheme
from sasprobe.devices.simulated.arm import SimulatedDevice, make_simulated
from sasprobe.protocol.pose import FLAG_FAULT

from tests.support.recordings import read_session, reference_ticks

SLOW_TICKS = range(300, 303)  # reads that take 8 ms (more than 3 periods)
BROKEN_TICKS = range(600, 610)  # reads that raise something other than DeviceFault


class FlakySim(SimulatedDevice):
    def read(self):
        if self.ticks in SLOW_TICKS:
            time.sleep(0.008)
        if self.ticks in BROKEN_TICKS:
            raise RuntimeError("driver bug")
        return super().read()


def make_flaky(argument, **options):
    sim = make_simulated(argument, **options)
    sim.__class__ = FlakySim
    return sim


def test_slow_reads_and_driver_exceptions_zero_the_force(tmp_path, monkeypatch):
    monkeypatch.setitem(SCHEMES, "flaky", DeviceScheme(f"{__name__}:make_flaky", "test", "flaky"))
    path = tmp_path / "w.mcap"
    config = DaemonConfig(
        device="flaky",
        pub=[f"ipc://{tmp_path}/p"],
        ctl=[f"ipc://{tmp_path}/c"],
        record=str(path),
        max_seconds=1.2,
    )
    assert Daemon(config).run() == 0
    s = read_session(path)
    slow = [i for i, e in s.errors.items() if e.startswith("device read took")]
    broken = [i for i, e in s.errors.items() if e == "device error: RuntimeError: driver bug"]
    # The three slowed reads, and any other read a loaded machine made take over 3 periods
    # (each read's own time is in the recording, read here with the mcap library and the
    # README's tables).
    read_ns = {t["pose"]["seq"]: t["read_ns"] for t in reference_ticks(path)}
    slow_seqs = {int(s.seq[i]) for i in slow}
    assert set(SLOW_TICKS) <= slow_seqs
    assert all(read_ns[q] > 3_000_000 for q in slow_seqs)
    faulted = {int(s.seq[i]) for i in s.errors}
    assert not [q for q, t in read_ns.items() if t > 3_000_000 and q not in faulted], (
        "a slow read went unflagged"
    )
    assert [s.seq[i] for i in broken] == list(BROKEN_TICKS)
    for i in slow + broken:
        assert s.flags[i] & FLAG_FAULT and not np.any(s.force_n[i])
    assert not s.flags[max(broken) + 1] & FLAG_FAULT or s.late_periods[max(broken) + 1] > 3
