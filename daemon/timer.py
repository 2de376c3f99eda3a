"""The haptic loop's timer: absolute deadlines on the monotonic clock, sleep then spin.

Tick k is due at t0 + k·period, so errors never accumulate (no drift). The loop sleeps
until `spin` before the deadline (the OS wakes a real-time thread late by tens of µs),
then spins on the clock for the rest, as CHAI3D's haptic thread and Force Dimension's
free-running loop spin for all of it. It never spins for more than half a period: a
SCHED_FIFO thread that never sleeps is throttled by the kernel (by default 50 ms of
every second, `sched_rt_runtime_us`), which costs far more than a late wake-up. A tick
that starts a full period or more after its deadline is an overrun: the deadlines it
missed are skipped (counted, never made up in a burst) and the schedule stays on the same
grid. What each tick does is daemon/loop.py.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

SPIN_S = 100e-6  # the last part of a period is spun rather than slept
HIST_BIN_NS = 1_000  # period-error histogram: 1 µs bins ...
HIST_BINS = 100_000  # ... up to 100 ms (larger errors land in the last bin)
RECENT_TICKS = 1024  # the window `sasprobe status` shows (about a second at 1 kHz)


@dataclass(frozen=True)
class Tick:
    seq: int  # tick number, +1 per executed tick
    index: int  # deadline number k (t0 + k·period) this tick serves
    deadline_ns: int  # the deadline it was originally due at
    start_ns: int  # when it started (after sleeping and spinning)
    late_ns: int  # start − deadline (≥ 0)
    missed: int  # deadlines skipped because this tick started a period or more late
    period_ns: int

    @property
    def late_periods(self) -> float:
        return self.late_ns / self.period_ns if self.period_ns else 0.0


class LoopStats:
    """Counters and a period-error histogram, cheap enough to update every tick."""

    def __init__(self, period_ns: int, clock: Callable[[], int]) -> None:
        self.period_ns = period_ns
        self._clock = clock
        self.recent = np.zeros(RECENT_TICKS, dtype=np.int64)  # start times, ring buffer
        self.recent_work = np.zeros(RECENT_TICKS, dtype=np.int64)  # time each tick's work took
        self.total_ticks = 0
        self.total_overruns = 0
        self.total_missed = 0
        self.reset()

    def reset(self) -> None:
        """Start a new measurement window (the totals keep counting)."""
        self.hist = np.zeros(HIST_BINS, dtype=np.int64)
        self.ticks = 0
        self.overruns = 0
        self.missed = 0
        self.failed_reads = 0  # ticks whose device read failed (the loop counts them)
        self.max_error_ns = 0
        self.max_work_ns = 0
        self.window_start_ns = self._clock()
        self._prev_start: int | None = None

    def record(self, tick: Tick) -> None:
        if self._prev_start is not None and self.period_ns:
            error = abs(tick.start_ns - self._prev_start - self.period_ns)
            self.hist[min(error // HIST_BIN_NS, HIST_BINS - 1)] += 1
            if error > self.max_error_ns:
                self.max_error_ns = error
        self._prev_start = tick.start_ns
        self.recent[self.total_ticks % RECENT_TICKS] = tick.start_ns
        self.ticks += 1
        self.total_ticks += 1
        if tick.missed:
            self.overruns += 1
            self.missed += tick.missed
            self.total_overruns += 1
            self.total_missed += tick.missed

    def record_work(self, work_ns: int) -> None:
        """How long the tick that was recorded last took from its start to its end."""
        self.recent_work[(self.total_ticks - 1) % RECENT_TICKS] = work_ns
        if work_ns > self.max_work_ns:
            self.max_work_ns = work_ns

    def summary(self) -> dict:
        """Rate and period error over the window since the last reset, and the recent second.
        The counters are taken first, together: the loop goes on ticking while this runs on
        another thread."""
        ticks, overruns, missed, failed_reads = (
            self.ticks,
            self.overruns,
            self.missed,
            self.failed_reads,
        )
        elapsed = max(self._clock() - self.window_start_ns, 1)
        counts = self.hist
        n = int(counts.sum())
        cumulative = np.cumsum(counts)

        def percentile(q: float) -> float | None:
            if n == 0:
                return None
            return float(np.searchsorted(cumulative, q * n) * HIST_BIN_NS / 1e3)  # bin floor, µs

        k = min(self.total_ticks, RECENT_TICKS)
        recent_rate = None
        recent_p99 = None
        work = self.recent_work[:k] / 1e3
        if k >= 3:
            order = (np.arange(self.total_ticks - k, self.total_ticks)) % RECENT_TICKS
            starts = self.recent[order]
            span = starts[-1] - starts[0]
            recent_rate = (k - 1) / (span / 1e9) if span > 0 else None
            if self.period_ns:
                recent_p99 = float(
                    np.percentile(np.abs(np.diff(starts) - self.period_ns), 99) / 1e3
                )
        return {
            "window_s": elapsed / 1e9,
            "ticks": ticks,
            "rate_hz": ticks / (elapsed / 1e9),
            "period_error_us": {
                "p50": percentile(0.5),
                "p99": percentile(0.99),
                "max": self.max_error_ns / 1e3 if n else None,
                "bin_us": HIST_BIN_NS / 1e3,
            },
            "overruns": overruns,
            "missed_deadlines": missed,
            "failed_reads": failed_reads,
            "work_us": {
                "recent_p50": float(np.percentile(work, 50)) if k else None,
                "recent_p99": float(np.percentile(work, 99)) if k else None,
                "max": self.max_work_ns / 1e3,
            },
            "recent": {"rate_hz": recent_rate, "period_error_p99_us": recent_p99, "ticks": k},
            "total": {
                "ticks": self.total_ticks,
                "overruns": self.total_overruns,
                "missed_deadlines": self.total_missed,
            },
        }


class FixedRateTimer:
    """Paces a loop at rate_hz (None: as fast as possible, e.g. a replay at --speed max)."""

    def __init__(
        self,
        rate_hz: float | None,
        spin_s: float = SPIN_S,
        clock: Callable[[], int] = time.monotonic_ns,
        sleep: Callable[[float], None] = time.sleep,
    ) -> None:
        if rate_hz is not None and not rate_hz > 0:
            raise ValueError(f"loop rate must be positive, got {rate_hz}")
        self.rate_hz = rate_hz
        self.period_ns = round(1e9 / rate_hz) if rate_hz else 0
        self.spin_ns = min(int(spin_s * 1e9), self.period_ns // 2)
        self._clock = clock
        self._sleep = sleep
        self._t0: int | None = None
        self._index = 0
        self._seq = 0
        self.stats = LoopStats(self.period_ns, clock)

    def start(self) -> None:
        """Anchor the schedule: tick 0 is due now."""
        self._t0 = self._clock()
        self._index = 0
        self.stats.reset()

    def deadline(self, index: int) -> int:
        assert self._t0 is not None, "start() the loop first"
        # Integer arithmetic from the anchor: no rounding error accumulates.
        return (
            self._t0 + (index * 1_000_000_000 * 1000) // round(self.rate_hz * 1000)
            if self.rate_hz
            else self._t0
        )

    def wait(self) -> Tick:
        """Block until the next deadline and return the tick due there."""
        if self._t0 is None:
            self.start()
        clock = self._clock
        deadline = self.deadline(self._index)
        now = clock()
        if self.period_ns and now < deadline:
            remaining = deadline - now
            if remaining > self.spin_ns:
                self._sleep((remaining - self.spin_ns) / 1e9)
            while clock() < deadline:
                pass
            now = clock()
        late = max(now - deadline, 0) if self.period_ns else 0
        missed = late // self.period_ns if self.period_ns else 0
        tick = Tick(
            seq=self._seq,
            index=self._index + missed,
            deadline_ns=deadline,
            start_ns=now,
            late_ns=late,
            missed=missed,
            period_ns=self.period_ns,
        )
        self._index += missed + 1
        self._seq += 1
        self.stats.record(tick)
        return tick
