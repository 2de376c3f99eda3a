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
    """The figure as a PNG; log value axes labelled with plain numbers (0.4, 2, 30), not
    4×10^-1, where matplotlib labels their minor ticks (a range of a decade or so)."""
    from matplotlib.ticker import LogFormatter

    class Plain(LogFormatter):
        def _num_to_string(self, x, vmin, vmax):
            return f"{x:g}"

    for ax in fig.axes:
        if ax.get_yscale() == "log":
            ax.yaxis.set_major_formatter(Plain(labelOnlyBase=False))
            ax.yaxis.set_minor_formatter(Plain(labelOnlyBase=False, minor_thresholds=(2, 0.4)))
    fig.tight_layout()
    fig.savefig(path)
    pyplot().close(fig)
    return path


def times_vs_atoms(path: Path, atoms, series, title: str, **title_style) -> Path:
    """Median times against atom count on log-log axes, as a PNG: `series` is
    [(seconds per structure, line style, label)]."""
    fig, ax = figure()
    for seconds, style, label in series:
        ax.loglog(atoms, [t * 1e3 for t in seconds], style, label=label)
    ax.set_xlabel("atoms")
    ax.set_ylabel("median time (ms)")
    ax.set_title(title, **title_style)
    ax.legend()
    return save(fig, path)


def annotate_apart(ax, notes, fontsize: float = 6) -> None:
    """Label points without labels overlapping: `notes` is [(x, y, text)] in data
    coordinates (the axes' scales and limits set); each label takes the first place beside
    its point (right above, right below, left above, left below) whose box meets no label
    placed before it, else the first."""
    fig = ax.figure
    fig.canvas.draw()  # the transforms of the final limits
    renderer = fig.canvas.get_renderer()
    placed = []  # label boxes in display coordinates
    for x, y, text in notes:
        best = None
        for dx, dy, ha, va in (
            (3, 2, "left", "bottom"),
            (3, -2, "left", "top"),
            (-3, 2, "right", "bottom"),
            (-3, -2, "right", "top"),
        ):
            label = ax.annotate(
                text,
                (x, y),
                fontsize=fontsize,
                xytext=(dx, dy),
                textcoords="offset points",
                ha=ha,
                va=va,
            )
            box = label.get_window_extent(renderer)
            if not any(box.overlaps(other) for other in placed):
                best = (label, box)
                break
            label.remove()
        if best is None:  # nowhere free: the first place
            label = ax.annotate(
                text, (x, y), fontsize=fontsize, xytext=(3, 2), textcoords="offset points"
            )
            best = (label, label.get_window_extent(renderer))
        placed.append(best[1])
