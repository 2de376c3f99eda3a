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
from sasprobe.devices.simulated.arm import SimulatedDevice, make_simulated
from sasprobe.devices.workspace.start import CUBE_FIT
from sasprobe.protocol.client import Subscriber

from tests.emulators.pty_serial import Rig
from tests.emulators.woodenhaptics_serial import WoodenHapticsEmulator
from tests.support.daemon_process import DaemonProcess
from tests.support.press import EMULATED_ARM_RATE, WHOLE, poses_until, pushing, wait_for

STALL_TICK, STALL_S = (
    1500,
    0.2,
)  # after the 1 s ramp, while the press script pushes into the molecule
SLACK_MS = (
    10.0  # scheduling on a shared machine: the bound is 3 ms; unguarded, the zero came after 200 ms
)


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
    monkeypatch.setitem(
        SCHEMES, "logged", DeviceScheme(f"{__name__}:make_logged", "test", "logged")
    )
    config = DaemonConfig(
        device="logged:press",
        pub=[f"ipc://{tmp_path}/p"],
        ctl=[f"ipc://{tmp_path}/c"],
        max_seconds=2.0,
        loop_stalls=[(STALL_TICK, STALL_S)],
        settings={"cube_half_A": CUBE_FIT},
    )  # the whole molecule: the press reaches it
    daemon = Daemon(config)
    assert daemon.run() == 0
    writes = daemon.device.writes
    loop_writes = [i for i, w in enumerate(writes) if w[2] == "loop"]
    # the injected stall: the loop's writes resume STALL_S later (a loaded machine's own short
    # stalls also bring the watchdog, but not for that long)
    before = next(
        i
        for i, j in zip(loop_writes, loop_writes[1:])
        if writes[j][0] - writes[i][0] > STALL_S * 0.9e9
    )
    last_tick, zero = writes[before], writes[before + 1]
    held = [w[1] for w in writes[max(0, before - 20) : before + 1] if w[2] == "loop"]
    assert max(held) > 0.05, (
        "the arm held no force when the loop stalled"
    )  # a lost tick may zero the very last
    assert zero[2] == "watchdog" and zero[1] == 0.0, (
        f"no zero from the watchdog during the stall: {zero}"
    )
    zeroed_after_ms = (zero[0] - last_tick[0]) / 1e6
    bound_ms = (
        STALL_PERIODS * 1e3 / daemon.rate_hz + 1e3 / daemon.rate_hz
    )  # the bound and one check interval
    assert zeroed_after_ms <= bound_ms + SLACK_MS, (
        f"zero came {zeroed_after_ms:.1f} ms after the last tick"
    )
    resumed = next(w for w in writes[before + 1 :] if w[2] == "loop")
    assert (
        resumed[0] - last_tick[0] >= STALL_S * 1e9 and resumed[1] == 0.0
    )  # the tick after it is faulted too
    stalls = daemon.loop.watchdog.as_dict()
    assert stalls["stalls"] >= 1 and stalls["longest_ms"] >= STALL_S * 1e3 * 0.95
    print(
        f"\nforce zeroed {zeroed_after_ms:.2f} ms after the last tick (bound {bound_ms:g} ms); "
        f"stall of {stalls['longest_ms']:.1f} ms reported"
    )


def _stall_in(commands: list, period_ns: int) -> tuple:
    """(the loop's last command, the first after it) around the stall: the longest run of
    zero-current commands that came sparsely (the loop sends one a period, the watchdog one
    every REZERO_PERIODS; the zeros of a calibrating arm come at the loop's pace)."""
    zero = (0, 0, 0)
    runs, start = [], None
    for i, (_, currents) in enumerate(commands + [(0, None)]):
        if currents == zero and start is None:
            start = i
        elif currents != zero and start is not None:
            runs.append((start, i - 1))
            start = None
    sparse = [
        (a, b)
        for a, b in runs
        if b - a >= 5
        and commands[b][0] - commands[a][0] > 0.2e9
        and (commands[b][0] - commands[a][0]) / (b - a) > 1.5 * period_ns
    ]
    assert sparse and sparse[0][0] > 0, "no stall in the commands the arm received"
    first = sparse[0][0]
    return commands[first - 1], commands[first]


class LoggedWoody(WoodenHapticsEmulator):
    """The emulated board, noting when each accepted command arrived and its currents."""

    def __init__(self, *args, **kwargs) -> None:
        self.commands: list = []
        super().__init__(*args, **kwargs)

    def loop(self) -> None:
        accepted = self.accepted
        super().loop()
        if self.accepted != accepted:
            self.commands.append((time.monotonic_ns(), tuple(self.last_command_ma)))


def test_the_serial_arm_gets_zero_current_from_the_watchdog_thread(tmp_path):
    """The real WoodenHaptics driver written from the watchdog thread while the loop sleeps
    (at the serial arms' test rate, 250 Hz: the bound is 3 periods, 12 ms)."""
    board = LoggedWoody(tmp_path)
    rig = Rig(board, f"woodenhaptics:{board.path}")
    rate_hz, stall_tick = float(EMULATED_ARM_RATE[1]), 1250  # 5 s in: pressing by then
    try:
        rig.hand.target = (0.0, 35.0, 0.0)  # above the molecule before the daemon starts
        wait_for(lambda: np.linalg.norm(board.stylus.now() - rig.hand.target) < 0.5)
        with DaemonProcess(
            *EMULATED_ARM_RATE,
            *WHOLE,
            "--inject-fault",
            f"stall@{stall_tick}+300",
            device=rig.device_spec,
        ) as daemon:
            sub = Subscriber(daemon.pub)
            poses_until(sub, lambda p: np.linalg.norm(p.tip_mm - board.stylus.now()) < 1.0, daemon)
            rig.hand.target = (0.0, 0.0, 0.0)  # down into the molecule
            pressing = poses_until(sub, pushing, daemon)
            assert pressing.seq < stall_tick, (
                "not pressing yet when the loop stalled (machine too slow)"
            )
            poses_until(sub, lambda p: p.seq > stall_tick + 100, daemon)
            trips = (
                board.watchdog_trips
            )  # (stopping the daemon leaves the board silent: its trips then)
            sub.close()
            daemon.stop()
    finally:
        rig.close()
    period_ns = int(1e9 / rate_hz)
    before, first_zero = _stall_in(board.commands, period_ns)
    gap_ms = (first_zero[0] - before[0]) / 1e6
    bound_ms = (STALL_PERIODS + 1) * period_ns / 1e6
    assert gap_ms <= bound_ms + SLACK_MS, (
        f"zero current came {gap_ms:.1f} ms after the last command"
    )
    assert (
        trips == 0
    )  # the thread kept it fed with zeros: the firmware's 100 ms watchdog never tripped
    print(
        f"\nWoodenHaptics at {rate_hz:g} Hz: zero current {gap_ms:.2f} ms after the loop's "
        f"last command (bound {bound_ms:g} ms)"
    )
