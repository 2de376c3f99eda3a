"""The loop's zero for a force the safety guard withheld: `withhold_force()`, never a
`write_force(0)`, which a driver may take for "the hand is in free space" (OpenHaptics,
after a force error). The simulated arm keeps a log of what the loop gave it each tick;
its fault injection makes reads fail at a tick of its own count, whatever the timing."""

from __future__ import annotations

import numpy as np
from sasprobe.daemon.service import Daemon, DaemonConfig
from sasprobe.devices.registry import SCHEMES, DeviceScheme
from sasprobe.devices.simulated.arm import SimulatedDevice, make_simulated
from sasprobe.devices.workspace.start import CUBE_FIT


class WatchedSim(SimulatedDevice):
    """The simulated arm with a log of what the loop gave it each tick."""

    def write_force(self, force_n) -> None:
        self.calls.append(("force", float(np.linalg.norm(force_n))))
        SimulatedDevice.write_force(self, force_n)

    def withhold_force(self) -> None:
        self.calls.append(("withheld", 0.0))
        SimulatedDevice.write_force(self, np.zeros(3))


def make_watched(argument, **options):
    sim = make_simulated(argument, **options)
    sim.__class__ = WatchedSim
    sim.calls = []
    return sim


def test_a_force_the_guard_withholds_goes_out_as_withheld_never_as_a_free_zero(
    tmp_path, monkeypatch
):
    """The first tick of the ramp (force scaled by 0), every tick whose read failed and the
    first good one after them (the ramp starts again) are withheld; ticks the engine computed
    from valid, on-time reads are written as they are. (A tick the loaded machine made late
    is withheld too, so only the ticks above are pinned down.)"""
    monkeypatch.setitem(SCHEMES, "watched", DeviceScheme(f"{__name__}:make_watched", "", ""))
    config = DaemonConfig(
        device="watched:press",
        pub=[f"ipc://{tmp_path}/p"],
        ctl=[f"ipc://{tmp_path}/c"],
        faults=["raise@300+5"],  # after the 300th force, five reads fail
        settings={"cube_half_A": CUBE_FIT},  # the whole molecule: the press reaches it
        max_seconds=1.5,
    )
    daemon = Daemon(config)
    daemon.run()
    calls = daemon.device.calls
    assert calls[0][0] == "withheld"  # the ramp starts at zero
    assert [kind for kind, _ in calls[300:306]] == ["withheld"] * 6
    assert any(kind == "force" and size > 0.0 for kind, size in calls[306:])
