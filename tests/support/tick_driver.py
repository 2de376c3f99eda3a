"""A daemon's ticks run by the test, one call a tick: counts that do not depend on how fast
the machine is (the daemon is built in the test's process; its timer never runs)."""

from __future__ import annotations

import time

from sasprobe.daemon.timer import Tick

PERIOD_NS = 1_000_000


class TickDriver:
    """Runs a daemon's ticks in the calling thread, numbered from 0."""

    def __init__(self, daemon, paced: bool = False) -> None:
        self.daemon = daemon
        self.seq = 0
        # paced: no tick before its period has come, so that a device whose clock counts the
        # ticks (the simulated arm) never stamps its reading later than the host's clock
        self._paced_from_ns = time.monotonic_ns() if paced else None

    def run(self, n: int, every: int = 0, action=None) -> None:
        """n ticks; action(seq) after every `every`-th."""
        for _ in range(n):
            if self._paced_from_ns is not None:
                due_ns = self._paced_from_ns + (self.seq + 1) * PERIOD_NS
                while (now := time.monotonic_ns()) < due_ns:
                    time.sleep((due_ns - now) / 1e9)
            now = time.monotonic_ns()
            self.daemon.loop.tick(Tick(self.seq, self.seq, now, now, 0, 0, PERIOD_NS))
            if every and self.seq % every == 0:
                action(self.seq)
            self.seq += 1

    def until(self, condition, what: str, timeout_s: float = 60.0) -> None:
        """Tick until condition() holds; a failure names what never came."""
        deadline = time.monotonic() + timeout_s
        while not condition():
            assert time.monotonic() < deadline, f"{what}: not within {timeout_s:g} s"
            self.run(10)
            time.sleep(0.001)
