"""A watchdog that does not need the loop: zero force when no tick has completed in time.

The safety guard zeroes the force of a tick that starts late, but only once the loop
runs that tick; while the loop is stalled (a blocked call, a thread holding the GIL
for long, the process preempted) the arm would keep its last force. This thread
watches the loop's heartbeat (the end of every tick) and, when none has come for
STALL_PERIODS periods, writes zero force itself — under the lock the loop writes
with, so the two never interleave inside a driver — and repeats it every
REZERO_PERIODS while the stall lasts (a driver may defer one write: the Falcon's
frames in flight). The loop asks `overdue_periods()` before each force: a tick that the
watchdog interrupted counts as that many periods late, which the safety guard faults
(zero force), and the stall is reported once with its length when the next tick
completes.

Bound: zero is written within STALL_PERIODS periods plus one check interval (a period,
and at least CHECK_MIN_S, so a fast loop is not interrupted every period to take the GIL)
of the last completed tick, provided this thread gets the CPU and the GIL. It runs at a
real-time priority above the loop's where the loop has one; a stall that holds the GIL
(a C extension that never releases it) or stops the whole process is beyond any
in-process watchdog and left to the device's own (devices/README.md, per driver).

The same thread supervises the control server (restarted if its thread ever ends).
"""

from __future__ import annotations

import logging
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass

from sasprobe.daemon.realtime import above_loop_priority

log = logging.getLogger("sasprobe")

# no completed tick for this long is a stall (3 ms at 1 kHz; the guard's late limit)
STALL_PERIODS = 3
# While stalled, zero is written again this often: a Falcon takes a frame only once its
# oldest is 5 ms old.
REZERO_PERIODS = 3
SUPERVISE_S = 0.5  # how often the control thread is checked
CHECK_MIN_S = 0.001  # the heartbeat is looked at every period, but at most this often


@dataclass
class Stall:
    length_ns: int  # from the last completed tick to the one that ended the stall
    # from the last completed tick to the watchdog's zero (None: could not write)
    zeroed_after_ns: int | None


class StallWatchdog:
    def __init__(
        self,
        device,
        write_lock: threading.Lock,
        period_ns: int,
        supervise: Callable[[], object] | None = None,
        clock: Callable[[], int] = time.monotonic_ns,
    ) -> None:
        self.device = device
        self.write_lock = write_lock
        self.period_ns = period_ns
        self.bound_ns = STALL_PERIODS * period_ns
        self.check_s = max(period_ns / 1e9, CHECK_MIN_S) if period_ns else 0.01
        self._supervise = supervise
        self._clock = clock
        self._state = threading.Lock()  # heartbeat vs check: a few hundred ns per tick
        self._last_tick_ns = clock()
        self._stalled_since_ns: int | None = None  # the last tick before the stall in progress
        self._fired_at_ns: int | None = None  # the first zero written in it
        self._last_zero_ns: int | None = None  # the latest
        self._interrupted = False  # the watchdog wrote zero since the loop last asked
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self.stalls = 0
        self.longest_ns = 0
        self.total_ns = 0
        self.last: Stall | None = None
        self.worst_zero_ns = 0  # slowest zero after a last tick, over all stalls
        # stalls during which the zero could not be written (a driver call held the lock)
        self.unwritten = 0

    # ------------------------------------------------------------------ the loop's side
    def heartbeat(self, now_ns: int) -> Stall | None:
        """A tick completed (call it holding the write lock, right after the force write);
        returns the stall it ended, if any (report it once)."""
        with self._state:
            self._last_tick_ns = now_ns
            started, self._stalled_since_ns = self._stalled_since_ns, None
            fired, self._fired_at_ns = self._fired_at_ns, None
            self._last_zero_ns = None
        if started is None:
            return None
        stall = Stall(now_ns - started, None if fired is None else fired - started)
        self.stalls += 1
        self.total_ns += stall.length_ns
        self.longest_ns = max(self.longest_ns, stall.length_ns)
        if stall.zeroed_after_ns is None:
            self.unwritten += 1
        else:
            self.worst_zero_ns = max(self.worst_zero_ns, stall.zeroed_after_ns)
        self.last = stall
        return stall

    def overdue_periods(self, now_ns: int) -> float:
        """0 for a tick on time; when the watchdog found this tick overdue (or zeroed the force
        during it), the periods since the last completed tick, which the guard then faults."""
        with self._state:
            interrupted, self._interrupted = self._interrupted, False
            if not (interrupted or self._stalled_since_ns is not None) or not self.period_ns:
                return 0.0
            return (now_ns - self._last_tick_ns) / self.period_ns

    # ------------------------------------------------------------------ the thread
    def start(self) -> None:
        self._last_tick_ns = self._clock()
        self._thread = threading.Thread(target=self._run, name="sasprobe-watchdog", daemon=True)
        self._thread.start()

    def stop(self) -> None:
        self._stop.set()
        if self._thread is not None:
            self._thread.join()

    def _run(self) -> None:
        above_loop_priority()
        next_supervise = 0.0
        while not self._stop.wait(self.check_s):
            if self.period_ns:
                self.check(self._clock())
            if self._supervise is not None and time.monotonic() >= next_supervise:
                next_supervise = time.monotonic() + SUPERVISE_S
                try:
                    self._supervise()
                except Exception:  # supervising must never end the watchdog
                    log.exception("supervising the control thread failed")

    def check(self, now_ns: int) -> None:
        """One look at the heartbeat; zero the force when the loop is overdue."""
        with self._state:
            last = self._last_tick_ns
            if now_ns - last <= self.bound_ns:
                return
            if self._stalled_since_ns != last:  # a new stall
                self._stalled_since_ns, self._fired_at_ns, self._last_zero_ns = last, None, None
            if (
                self._last_zero_ns is not None
                and now_ns - self._last_zero_ns < REZERO_PERIODS * self.period_ns
            ):
                return
        if not self._zero(last):
            return  # tried again at the next check
        now = self._clock()
        with self._state:
            if self._stalled_since_ns == last:  # the loop did not come back meanwhile
                self._last_zero_ns = now
                self._fired_at_ns = self._fired_at_ns or now
                self._interrupted = True

    def _zero(self, last_tick_ns: int) -> bool:
        if not self.write_lock.acquire(timeout=self.period_ns / 1e9):
            # the loop is inside a driver write: only the device's own watchdog helps now
            return False
        try:
            if self._last_tick_ns != last_tick_ns:
                return False  # the loop wrote and beat (under this lock) while we waited for it
            self.device.zero_force_now()
            return True
        except Exception as exc:  # a failing device: the loop will see it too
            log.info("watchdog could not write zero force: %s", exc)
            return False
        finally:
            self.write_lock.release()

    def as_dict(self) -> dict:
        last = self.last
        return {
            "bound_ms": self.bound_ns / 1e6,
            "stalls": self.stalls,
            "longest_ms": self.longest_ns / 1e6,
            "total_ms": self.total_ns / 1e6,
            "last_ms": None if last is None else last.length_ns / 1e6,
            "worst_zero_after_ms": self.worst_zero_ns / 1e6
            if self.stalls > self.unwritten
            else None,
            "unwritten": self.unwritten,
        }
