"""Matplotlib set-up shared by the benchmark charts (headless Agg backend).

Matplotlib is imported on the first chart, not with this module: every `sasprobe` command
registers the benchmarks' options at start-up, and pyplot alone took a second of it (and
complains about an unusable $HOME)."""

from __future__ import annotations

from pathlib import Path


def pyplot():
    """matplotlib.pyplot on the Agg backend (no window, whatever the display)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def figure(width: float = 6.4, height: float = 4.0):
    fig, ax = pyplot().subplots(figsize=(width, height), dpi=110)
    ax.grid(True, which="both", alpha=0.3)
    return fig, ax


def save(fig, path: Path) -> Path:
    fig.tight_layout()
    fig.savefig(path)
    pyplot().close(fig)
    return path
