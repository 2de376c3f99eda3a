"""The findings chart: passage radius and force along the explored path, with the marks.

x is the distance travelled along the path (Å), the way tunnel profiles are drawn. Top:
the passage radius (the widest sphere across the path), the probe's own radius, the
clearance at the probe centre (it equals the probe radius wherever the probe touched),
the stretches in contact shaded and the bottleneck marked with the atoms that form it.
Bottom: the largest force on the hand over each stretch. The marks are numbered lines
through both.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from sasprobe.daemon.findings.bottleneck import Profile
from sasprobe.daemon.findings.path import ExploredPath
from sasprobe.molecule.clearance import OPEN_RADIUS_A

PASSAGE_COLOR = "#1f5fa8"
CONTACT_COLOR = "#f2c58f"
PROBE_COLOR = "#c0392b"
MARK_COLOR = "#6a3d9a"


def atom_names(atoms: list[dict], limit: int = 4) -> str:
    names = [f"{a['name']}{a['number']}{a['icode']} {a['atom']}" for a in atoms[:limit]]
    return ", ".join(names) + (f" +{len(atoms) - limit}" if len(atoms) > limit else "")


def draw_chart(
    out: Path,
    title: str,
    path: ExploredPath,
    prof: Profile,
    probe_radius_A: float,
    bottleneck: dict | None,
    marks: list[dict],
    verdict: str,
) -> None:
    from matplotlib.figure import Figure  # no pyplot: no global state, no display

    x = path.length_A
    passage = np.minimum(prof.passage_A, OPEN_RADIUS_A)
    fig = Figure(figsize=(10, 6.2), layout="constrained")
    top, bottom = fig.subplots(2, 1, sharex=True, height_ratios=(3, 1.3))
    for ax in (top, bottom):  # the stretches in contact, as one shaded band per axis
        ax.fill_between(
            x,
            0,
            1,
            where=path.contact,
            step="mid",
            transform=ax.get_xaxis_transform(),
            color=CONTACT_COLOR,
            alpha=0.45,
            lw=0,
            label="probe touching the surface" if ax is top else None,
        )
    top.plot(
        x,
        passage,
        color=PASSAGE_COLOR,
        lw=1.8,
        label="passage radius (widest sphere across the path)",
    )
    top.plot(
        x,
        np.minimum(prof.clearance_A, OPEN_RADIUS_A),
        color="0.45",
        lw=0.9,
        label="clearance at the probe centre",
    )
    top.axhline(
        probe_radius_A,
        color=PROBE_COLOR,
        ls="--",
        lw=1.2,
        label=f"probe radius {probe_radius_A:g} Å",
    )
    top.axhspan(
        OPEN_RADIUS_A,
        OPEN_RADIUS_A * 1.08,
        color="0.88",
        lw=0,
        label=f"≥ {OPEN_RADIUS_A:g} Å: open, no passage around the path",
    )
    if bottleneck is not None:
        bx, by = bottleneck["path_length_A"], bottleneck["radius_A"]
        right = bx > (x[0] + x[-1]) / 2  # the label goes toward the middle of the chart
        top.plot([bx], [by], "o", color=PROBE_COLOR, ms=7, zorder=5)
        top.annotate(
            f"bottleneck {by:.2f} Å at {bottleneck['t_s']:.1f} "
            f"s\n{atom_names(bottleneck['atoms'])}",
            (bx, by),
            xytext=(-12 if right else 12, -30),
            textcoords="offset points",
            fontsize=8.5,
            color=PROBE_COLOR,
            ha="right" if right else "left",
            arrowprops={"arrowstyle": "-", "color": PROBE_COLOR, "lw": 0.8},
        )
    top.set_ylim(0, OPEN_RADIUS_A * 1.08)
    top.set_ylabel("radius (Å)")
    fig.suptitle(f"{title}\n{verdict}", fontsize=10.5, x=0.01, ha="left")
    bottom.fill_between(x, path.force_max_N, color="0.3", step="pre", lw=0)
    bottom.set_ylabel("force on the\nhand (N)")
    bottom.set_xlabel("distance travelled along the explored path (Å)")
    bottom.set_ylim(0, max(float(path.force_max_N.max()) * 1.15, 0.05))
    for mark in marks:
        k = int(np.searchsorted(path.t_s, mark["t_s"]))
        mx = x[min(k, path.n_points - 1)]
        for ax in (top, bottom):
            ax.axvline(mx, color=MARK_COLOR, lw=1.0, ls=":")
        top.annotate(
            str(mark["id"]),
            (mx, OPEN_RADIUS_A * 1.04),
            ha="center",
            va="center",
            fontsize=8,
            color="white",
            bbox={"boxstyle": "circle,pad=0.25", "fc": MARK_COLOR, "ec": "none"},
        )
    if marks:
        names = "; ".join(f"{m['id']} ({m['t_s']:.1f} s) {m['label']}" for m in marks[:8]) + (
            " …" if len(marks) > 8 else ""
        )
        fig.text(0.01, 0.005, f"marks  {names}", fontsize=8, color=MARK_COLOR, va="bottom")
    top.legend(
        loc="lower left",
        bbox_to_anchor=(0.0, 1.01),
        ncol=3,
        fontsize=8,
        frameon=False,
        borderaxespad=0.0,
        handlelength=1.6,
    )
    top.set_xlim(x[0], max(x[-1], x[0] + path.spacing_A))
    fig.savefig(out, dpi=110)
