"""A loop stalled on purpose (`--inject-fault stall@TICK+MS`): the watchdog thread zeroes the
arm's force within its bound, and the stall is reported with its length.

The arm here is the simulated one with a log of its own: every force it is given, with the
time it arrived (monotonic) and whether the loop or the watchdog wrote it; the log is the
oracle, not the daemon's own report.
"""

from __future__ import annotations

import time

import numpy as np

from sasprobe.daemon.service import Daemon, DaemonConfig
from sasprobe.daemon.watchdog import STALL_PERIODS
from sasprobe.devices.registry import SCHEMES, DeviceScheme
from sasprobe.devices.simulated import SimulatedDevice, make_simulated
from sasprobe.protocol.client import Subscriber
from tests.daemon_process import DaemonProcess
from tests.emulators.physics import MovableHand
from tests.emulators.woodenhaptics_serial import WoodenHapticsEmulator
from tests.test_devices_daemon import exchanges, poses_until, pushing

STALL_TICK, STALL_S = 1500, 0.2  # after the 1 s ramp, while the press script pushes into the molecule
SLACK_MS = 10.0  # scheduling on a shared machine: the bound is 3 ms; unguarded, the zero came after 200 ms


class LoggedSim(SimulatedDevice):
    def write_force(self, force_n) -> None:
        self.writes.append((time.monotonic_ns(), float(np.linalg.norm(force_n)), "loop"))
        super().write_force(force_n)

    def zero_force_now(self) -> None:
        self.writes.append((time.monotonic_ns(), 0.0, "watchdog"))
        super().zero_force_now()


def make_logged(argument, **options):
    sim = make_simulated(argument, **options)
    sim.__class__ = LoggedSim
    sim.writes = []
    return sim


def test_a_stalled_loop_has_its_force_zeroed_within_the_bound(tmp_path, monkeypatch):
    monkeypatch.setitem(SCHEMES, "logged", DeviceScheme(f"{__name__}:make_logged", "test", "logged"))
    config = DaemonConfig(device="logged:press", pub=[f"ipc://{tmp_path}/p"], ctl=[f"ipc://{tmp_path}/c"],
                          max_seconds=2.0, loop_stalls=[(STALL_TICK, STALL_S)])
    daemon = Daemon(config)
    assert daemon.run() == 0
    writes = daemon.device.writes
    stalled = next(i for i in range(1, len(writes)) if writes[i][0] - writes[i - 1][0] > 50e6
                   or writes[i][2] == "watchdog")
    last_tick, zero = writes[stalled - 1], writes[stalled]
    assert last_tick[2] == "loop" and last_tick[1] > 0.05, "the arm held no force when the loop stalled"
    assert zero[2] == "watchdog" and zero[1] == 0.0, f"no zero from the watchdog during the stall: {zero}"
    zeroed_after_ms = (zero[0] - last_tick[0]) / 1e6
    bound_ms = STALL_PERIODS * 1e3 / daemon.rate_hz + 1e3 / daemon.rate_hz  # the bound and one check interval
    assert zeroed_after_ms <= bound_ms + SLACK_MS, f"zero came {zeroed_after_ms:.1f} ms after the last tick"
    resumed = next(w for w in writes[stalled:] if w[2] == "loop")
    assert resumed[0] - last_tick[0] >= STALL_S * 1e9 and resumed[1] == 0.0  # the tick after it is faulted too
    stalls = daemon.watchdog.as_dict()
    assert stalls["stalls"] >= 1 and stalls["longest_ms"] >= STALL_S * 1e3 * 0.95
    print(f"\nforce zeroed {zeroed_after_ms:.2f} ms after the last tick (bound {bound_ms:g} ms); "
          f"stall of {stalls['longest_ms']:.1f} ms reported")


def _stall_in(commands: list) -> tuple:
    """(the loop's last command, the first after it) around the stall: the longest-lasting run of
    zero-current commands that came sparsely (the loop sends one a millisecond, the watchdog one
    every REZERO_PERIODS; the zeros before calibration come at the loop's pace)."""
    runs, start = [], None
    for i, (_, line) in enumerate(commands + [(0, b"end")]):
        if line == b"[0,0,0]" and start is None:
            start = i
        elif line != b"[0,0,0]" and start is not None:
            runs.append((start, i - 1))
            start = None
    sparse = [(a, b) for a, b in runs if b - a >= 10 and commands[b][0] - commands[a][0] > 0.2e9
              and (commands[b][0] - commands[a][0]) / (b - a) > 2e6]
    assert sparse and sparse[0][0] > 0, "no stall in the commands the arm received"
    first = sparse[0][0]
    return commands[first - 1], commands[first]


class LoggedWoodenHaptics(WoodenHapticsEmulator):
    """The emulated Teensy, noting when each command arrived and the currents it asked for."""

    commands: list = []  # set per instance before the emulator thread starts (class default: the first use)

    def __init__(self, *args, **kwargs) -> None:
        self.commands = []
        super().__init__(*args, **kwargs)

    def _command(self, line: bytes) -> None:
        self.commands.append((time.monotonic_ns(), line))
        super()._command(line)


def test_the_serial_arm_gets_zero_current_from_the_watchdog_thread(tmp_path):
    """The real WoodenHaptics driver written from the watchdog thread while the loop sleeps."""
    hand = MovableHand()
    emu = LoggedWoodenHaptics(tmp_path, hand=hand)
    hand.target = tuple(emu.stylus.position)  # at home: the driver calibrates
    stall_tick = 3000
    try:
        with DaemonProcess("--inject-fault", f"stall@{stall_tick}+300", device=f"woodenhaptics:{emu.path}") as daemon:
            sub = Subscriber(daemon.pub)
            poses_until(sub, lambda p: True, daemon)
            exchanges(emu, 100)
            hand.target = (0.0, 0.0, 0.0)  # into the molecule: pushing before the stall
            poses_until(sub, pushing, daemon)
            poses_until(sub, lambda p: p.seq > stall_tick + 400, daemon)
            trips = emu.watchdog_trips  # (stopping the daemon leaves the arm silent: the firmware's trips then)
            sub.close()
            daemon.stop()
    finally:
        emu.stop()
    before, first_zero = _stall_in(emu.commands)
    assert before[1] != b"[0,0,0]", "the arm was not pushing when the loop stalled"
    assert first_zero[1] == b"[0,0,0]", f"the watchdog's command was {first_zero[1]!r}"
    gap_ms = (first_zero[0] - before[0]) / 1e6
    assert gap_ms <= STALL_PERIODS + 1 + SLACK_MS, f"zero current came {gap_ms:.1f} ms after the last command"
    assert trips == 0  # the thread kept it fed with zeros: the firmware's 100 ms watchdog never tripped
    print(f"\nWoodenHaptics: zero current {gap_ms:.2f} ms after the loop's last command")
