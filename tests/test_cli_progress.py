"""Progress of long jobs (sasprobe/common/progress.py): a bar that waits before its first
unit shows it is working, and its ETA is timed from that unit, so a long read before the
work does not pass for slow work; `sasprobe replay` shows each of its steps."""

from __future__ import annotations

import argparse
import io
import threading
from pathlib import Path

from sasprobe.protocol.recording import Summary

from sasprobe.common import progress


class Terminal(io.StringIO):
    """A stderr that says it is a terminal and tells when some text has been drawn."""

    def __init__(self) -> None:
        super().__init__()
        self.drawn = threading.Condition()

    def isatty(self) -> bool:
        return True

    def write(self, text: str) -> int:
        with self.drawn:
            n = super().write(text)
            self.drawn.notify_all()
        return n

    def wait_for(self, condition, timeout_s: float = 30.0) -> bool:
        with self.drawn:
            return self.drawn.wait_for(lambda: condition(self.getvalue()), timeout_s)


def terminal(monkeypatch) -> Terminal:
    """A Terminal as sys.stderr; set in the test's body (pytest puts its own capture back
    between a fixture and the test)."""
    stream = Terminal()
    monkeypatch.setattr("sys.stderr", stream)
    return stream


def eta_s(bar) -> float:
    """The remaining time the bar shows, as tqdm computes it."""
    d = bar.format_dict
    rate = d["rate"] or d["n"] / d["elapsed"]
    return (d["total"] - d["n"]) / rate


def test_the_eta_is_timed_from_the_first_unit(monkeypatch):
    """54 s of reading, then 1000 ticks a second: the ETA is what is left at that rate
    (an ETA timed from the start said 9,219 h on a 10-minute recording)."""
    terminal(monkeypatch)
    now = [0.0]
    bar = progress.progress_bar(600_000, "verify", unit="tick")
    bar._time = lambda: now[0]
    bar.start_t = bar.last_print_t = 0.0
    now[0] = 54.0
    for _ in range(3):
        bar.update(1000)
        now[0] += 1.0
    left = (600_000 - 3000) / 1000
    assert left / 2 < eta_s(bar) < left * 2, eta_s(bar)
    bar.close()


def test_a_bar_that_has_counted_nothing_is_redrawn(monkeypatch):
    stream = terminal(monkeypatch)
    monkeypatch.setattr(progress, "REDRAW_S", 0.01)
    bar = progress.working("read session.mcap")
    try:
        assert stream.wait_for(lambda text: text.count("read session.mcap: ") >= 3)
    finally:
        bar.close()


def test_replay_shows_that_it_reads_the_recording(monkeypatch):
    """`sasprobe replay FILE` reads the whole file before it says anything: a step that
    draws its line while it works."""
    from sasprobe.cli.commands import replay

    stream = terminal(monkeypatch)
    seen = []

    def slow_summarize(path):
        seen.append(stream.wait_for(lambda text: f"read {Path(path).name}: " in text))
        return Summary(
            path=str(path),
            finished=True,
            bytes_total=1,
            bytes_readable=1,
            format=2,
            counts={"ticks": 1},
            first_log_ns=0,
            last_log_ns=10**9,
            ticks=1,
            seq_gaps=0,
            structures=["1crn"],
            metadata={},
        )

    monkeypatch.setattr("sasprobe.protocol.recording.summarize", slow_summarize)
    args = argparse.Namespace(
        file=Path("session.mcap"),
        verify=False,
        recover=None,
        video=None,
        html=None,
        findings=None,
        probe_radius=None,
        json=True,
    )
    assert replay.run(args) == 0
    assert seen == [True]
