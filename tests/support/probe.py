"""Measuring what a probe does to the loop: pose gaps the machine's own pauses do not explain."""

from __future__ import annotations

import json
import subprocess
import sys
import time

from tests.conftest import REPO_ROOT
from tests.support.bounded import lines_until


class PoseWatch:
    """tests/support/pose_watch.py in its own process (so nothing the test does holds its GIL)."""

    def __init__(self, pub: str) -> None:
        self.proc = subprocess.Popen(
            [sys.executable, "-m", "tests.support.pose_watch", pub],
            cwd=REPO_ROOT,
            stdin=subprocess.PIPE,
            stdout=subprocess.PIPE,
            text=True,
        )
        lines = lines_until(self.proc.stdout, lambda line: True, 60.0)
        if [line.strip() for line in lines] != ["ready"]:
            self.proc.kill()
            raise AssertionError(f"the pose watcher got no pose from {pub} within 60 s")
        self.result: dict | None = None

    def finish(self) -> dict:
        """Its report; AssertionError when any pose it received broke the protocol."""
        if self.result is None:
            out, _ = self.proc.communicate(timeout=30)  # stdin closed: it reports and ends
            self.result = json.loads(out)
        assert self.result["invalid"] == 0, (
            f"{self.result['invalid']} of {self.result['poses']} poses broke the protocol: "
            f"{self.result['why']}"
        )
        return self.result

    def __enter__(self) -> PoseWatch:
        return self

    def __exit__(self, *exc) -> None:
        if self.proc.poll() is None:
            self.finish()


def unexplained_ms(result: dict, start_ns: int, end_ns: int) -> tuple[float, float]:
    """(longest pose gap, longest part of a gap not covered by a machine pause) within
    [start_ns, end_ns], in ms (at least one period: no gap over 2 ms is 1 ms)."""
    longest = rest = 1.0
    for a, b in result["gaps"]:
        if b < start_ns or a > end_ns:
            continue
        covered = sum(max(0, min(b, d) - max(a, c)) for c, d in result["pauses"])
        longest = max(longest, (b - a) / 1e6)
        rest = max(rest, (b - a - covered) / 1e6)
    return longest, rest


def now_ns() -> int:
    return time.monotonic_ns()
