"""Progress display for long jobs (stderr, so stdout stays clean for --json)."""

from __future__ import annotations

import sys
from collections.abc import Iterable, Iterator
from typing import TypeVar

from tqdm import tqdm

T = TypeVar("T")


def _style() -> dict:
    """Redraw often on a terminal, rarely into a log, and leave no bar behind in logs."""
    interactive = sys.stderr.isatty()
    return {
        "file": sys.stderr,
        "mininterval": 0.1 if interactive else 10.0,
        "leave": interactive,
        "dynamic_ncols": True,
    }


def progress(iterable: Iterable[T], desc: str, total: int | None = None) -> Iterator[T]:
    """Wrap an iterable with a progress bar."""
    return iter(tqdm(iterable, desc=desc, total=total, **_style()))


def progress_bar(total: float | None, desc: str, unit: str = "it", **options) -> tqdm:
    """A manually advanced bar (call .update(n), then .close()); options go to tqdm (e.g.
    bar_format)."""
    return tqdm(total=total, desc=desc, unit=unit, **_style(), **options)
