"""Benchmarks behind `sasprobe bench`: one module per area, each with `run(ctx) -> BenchResult`.

Timing lives here, never in tests. Every figure is a median over repeats, and
comparisons are ratios measured in the same run.
"""

from __future__ import annotations

import importlib
import statistics
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

# The order `sasprobe bench` runs them in; a name whose module is absent is skipped.
ORDER = ["startup", "grid", "sas", "haptics", "daemon", "render", "lighting", "web"]
# Run by name only (`sasprobe bench NAME`), each writing its own part of the page: they want
# a machine chosen for them (rates) or take long (replay, soak).
ON_THEIR_OWN = ["rates", "replay", "soak"]


@dataclass
class BenchContext:
    quick: bool = False
    out_dir: Path | None = None  # charts go here when set
    # Every code path once at its smallest (the smallest structure, tiny frames, one repeat):
    # a check that the benchmark runs, in seconds; its figures measure nothing.
    smoke: bool = False

    def chart_path(self, name: str) -> Path | None:
        if self.out_dir is None:
            return None
        self.out_dir.mkdir(parents=True, exist_ok=True)
        return self.out_dir / name


@dataclass
class BenchResult:
    name: str
    data: dict  # JSON-serialisable figures
    markdown: str  # a section of report.md: tables and what they show
    charts: list[Path] = field(default_factory=list)


def load(name: str):
    """The benchmark module for a name, or None when that benchmark is not built yet."""
    try:
        return importlib.import_module(f"sasprobe.cli.bench.{name}")
    except ModuleNotFoundError as exc:
        if exc.name == f"sasprobe.cli.bench.{name}":
            return None
        raise


def available() -> list[str]:
    """The benchmarks of a plain `sasprobe bench`."""
    return [name for name in ORDER if load(name) is not None]


def on_their_own() -> list[str]:
    """The benchmarks run by name only."""
    return [name for name in ON_THEIR_OWN if load(name) is not None]


def median_time(fn: Callable[[], object], repeats: int) -> float:
    """Median wall time of `repeats` calls, seconds."""
    samples = []
    for _ in range(max(1, repeats)):
        t0 = time.perf_counter()
        fn()
        samples.append(time.perf_counter() - t0)
    return statistics.median(samples)
