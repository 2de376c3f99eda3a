"""The fixed-rate loop on a simulated clock (exact) and on the real one (behaviour only)."""

from __future__ import annotations

import time

import pytest
from sasprobe.daemon.timer import FixedRateTimer


class FakeClock:
    """A monotonic ns clock that sleep() and a per-call cost advance."""

    def __init__(self, cost_ns: int = 1_000) -> None:
        self.now = 10_000_000_000
        self.cost_ns = cost_ns
        self.sleeps: list[float] = []
        self.oversleep_ns = 0

    def clock(self) -> int:
        self.now += self.cost_ns
        return self.now

    def sleep(self, seconds: float) -> None:
        self.sleeps.append(seconds)
        self.now += int(seconds * 1e9) + self.oversleep_ns


def test_absolute_deadlines_do_not_drift():
    fake = FakeClock()
    fake.oversleep_ns = 80_000  # the OS wakes us 80 µs late, every time
    loop = FixedRateTimer(1000.0, spin_s=150e-6, clock=fake.clock, sleep=fake.sleep)
    loop.start()
    t0 = loop.deadline(0)
    ticks = [loop.wait() for _ in range(5000)]
    for k, tick in enumerate(ticks):
        assert tick.deadline_ns == t0 + k * 1_000_000  # on the grid, no accumulated error
        assert 0 <= tick.late_ns < 5_000  # spin absorbs the late wake-up
    assert all(s < 1e-3 for s in fake.sleeps)
    assert loop.stats.summary()["overruns"] == 0


def test_overruns_skip_missed_deadlines_and_stay_on_the_grid():
    fake = FakeClock()
    loop = FixedRateTimer(500.0, clock=fake.clock, sleep=fake.sleep)  # 2 ms period
    loop.start()
    t0 = loop.deadline(0)
    loop.wait()
    fake.now += 7_300_000  # the tick's work took 7.3 ms
    tick = loop.wait()
    # Due at 2 ms, it starts at 7.3 ms: it serves the 6 ms deadline and two ticks are lost.
    assert tick.missed == 2
    assert tick.index == 3 and tick.deadline_ns == t0 + 2_000_000
    assert tick.late_periods == pytest.approx(
        (7.3 - 2) / 2, abs=0.01
    )  # the watchdog sees 2.65 periods
    nxt = loop.wait()  # ... and the next one is due at 8 ms, not 9.3 ms
    assert nxt.deadline_ns == t0 + 8_000_000 and nxt.missed == 0
    summary = loop.stats.summary()
    assert summary["overruns"] == 1 and summary["missed_deadlines"] == 2


def test_fractional_rates_use_exact_integer_deadlines():
    fake = FakeClock()
    loop = FixedRateTimer(333.0, clock=fake.clock, sleep=fake.sleep)
    loop.start()
    t0 = loop.deadline(0)
    assert loop.deadline(333_000) - t0 == 1_000_000_000_000  # 1000 s later, to the ns


def test_free_running_loop_never_sleeps():
    fake = FakeClock()
    loop = FixedRateTimer(None, clock=fake.clock, sleep=fake.sleep)
    ticks = [loop.wait() for _ in range(100)]
    assert not fake.sleeps and [t.seq for t in ticks] == list(range(100))
    assert all(t.late_ns == 0 and t.missed == 0 for t in ticks)


def test_real_clock_keeps_the_average_rate():
    # Behaviour, not speed: over 0.3 s the schedule is absolute, so the tick count
    # matches elapsed time even if individual ticks are late on a busy machine.
    loop = FixedRateTimer(1000.0)
    loop.start()
    t_start = time.monotonic_ns()
    last = None
    while time.monotonic_ns() - t_start < 300_000_000:
        last = loop.wait()
    assert last.start_ns >= last.deadline_ns
    assert abs(last.index - (last.start_ns - t_start) / 1e6) < 3
