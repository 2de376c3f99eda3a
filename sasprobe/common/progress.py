"""Progress display for long jobs (stderr, so stdout stays clean for --json).

A step often waits before its first unit (a recording is read before its ticks are
recomputed, a structure is loaded before its frames are drawn). A bar shows that wait:
it is redrawn every second until its first unit, so its elapsed time says the step is
working, and its rate, and so its ETA, is timed from the first unit, so the wait does
not pass for slow units.
"""

from __future__ import annotations

import sys
import threading
from collections.abc import Iterable, Iterator
from typing import TypeVar

from tqdm import tqdm

T = TypeVar("T")

REDRAW_S = 1.0  # how often a bar that has counted nothing yet is redrawn (on a terminal)


def _style() -> dict:
    """Redraw often on a terminal, rarely into a log, and leave no bar behind in logs."""
    interactive = sys.stderr.isatty()
    return {
        "file": sys.stderr,
        "mininterval": 0.1 if interactive else 10.0,
        "leave": interactive,
        "dynamic_ncols": True,
    }


class Bar(tqdm):
    """A tqdm bar redrawn until its first unit, with its rate timed from that unit."""

    def __init__(self, *args, **kwargs) -> None:
        self._counting = threading.Event()
        super().__init__(*args, **kwargs)
        if not self.disable:
            threading.Thread(target=self._redraw_until_counting, daemon=True).start()

    def _redraw_until_counting(self) -> None:
        while not self._counting.wait(max(REDRAW_S, self.mininterval)):
            if self._time() >= self.start_t + self.delay:
                self.refresh()
                self.last_print_t = self._time()  # shown: close() clears it

    def update(self, n: float = 1) -> bool | None:
        if n and not self._counting.is_set():
            self._counting.set()
            self.start_t = self.last_print_t = self._time()  # the wait was no unit's time
        return super().update(n)

    def refresh(self, *args, **kwargs) -> None:
        if not self.disable:  # the redrawing thread may come after close()
            super().refresh(*args, **kwargs)

    def close(self) -> None:
        self._counting.set()
        super().close()


def progress(iterable: Iterable[T], desc: str, total: int | None = None) -> Iterator[T]:
    """Wrap an iterable with a progress bar."""
    return iter(tqdm(iterable, desc=desc, total=total, **_style()))


def progress_bar(total: float | None, desc: str, unit: str = "it", **options) -> Bar:
    """A manually advanced bar (call .update(n), then .close()); options go to tqdm (e.g.
    bar_format)."""
    return Bar(total=total, desc=desc, unit=unit, **_style(), **options)


def working(desc: str) -> Bar:
    """A step without a count (reading a file): once it has taken REDRAW_S, its name and
    elapsed time, redrawn every second until .close() (a quick step, or one that fails at
    once, shows nothing)."""
    return progress_bar(None, desc, bar_format="{desc}: {elapsed}", delay=REDRAW_S)
