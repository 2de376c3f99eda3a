"""Progress display for long jobs (stderr, so stdout stays clean for --json)."""

from __future__ import annotations

import sys
from typing import Iterable, Iterator, TypeVar

from tqdm import tqdm

T = TypeVar("T")


def progress(iterable: Iterable[T], desc: str, total: int | None = None) -> Iterator[T]:
    """Wrap an iterable with a progress bar; redraw rarely when stderr is not a terminal."""
    interactive = sys.stderr.isatty()
    return iter(
        tqdm(
            iterable,
            desc=desc,
            total=total,
            file=sys.stderr,
            mininterval=0.1 if interactive else 10.0,
            leave=interactive,
            dynamic_ncols=True,
        )
    )


def progress_bar(total: float | None, desc: str, unit: str = "it", **options) -> tqdm:
    """A manually advanced bar (call .update(n), then .close()); options go to tqdm (e.g. bar_format)."""
    interactive = sys.stderr.isatty()
    return tqdm(
        total=total,
        desc=desc,
        unit=unit,
        file=sys.stderr,
        mininterval=0.1 if interactive else 10.0,
        leave=interactive,
        dynamic_ncols=True,
        **options,
    )
