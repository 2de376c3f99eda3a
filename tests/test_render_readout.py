"""A headless picture following a daemon says where the probe is, as the window does: the
readout (haptic rate, force, touched atom, clearance) in its top-left corner; and with
--overview-first its first frames show where the cube sits on the molecule.

The source is a stand-in for a daemon (a fixed readout, the options' cube and probe), so
the pictures compared differ only by what is asked of the renderer."""

from __future__ import annotations

import imageio.v2 as imageio
import numpy as np
from sasprobe.molecule import load_structure_or_default
from sasprobe.render import app
from sasprobe.render.gl.targets import KIND_BACKBONE
from sasprobe.render.readout_text import MARGIN, readout_lines
from sasprobe.render.source import Readout, StaticSource
from sasprobe.render.text import text_image

READOUT = Readout(
    haptic_hz=1000.0,
    force_n=0.42,
    touched="A ASP 43 CB",
    continuous_force_n=0.88,
    peak_force_n=3.3,
    clearance_A=1.4,
    passage_A=3.07,
    bottleneck_A=2.14,
    status="waiting for daemon at tcp://127.0.0.1:5555",  # the headless run has waited already
)
SIZE = (480, 270)


class FollowedDaemon(StaticSource):
    """A file's structure with a daemon's readout and the workspace view's axes."""

    follows_daemon = True

    def readout(self) -> Readout:
        return READOUT

    def view_axes(self):
        return np.eye(3)


def render(monkeypatch, tmp_path, name: str, **options):
    structure = load_structure_or_default(None)
    top = structure.positions[np.argmax(structure.positions[:, 2])]
    monkeypatch.setattr(app, "open_source", lambda opts: FollowedDaemon(structure))
    opts = app.RenderOptions(
        headless=True,
        size=SIZE,
        frames=1,
        out=tmp_path / f"{name}.png",
        gbuffer=tmp_path / f"{name}.npz",
        nav_cube=[*top, 6.0],
        probe=list(top + [0.0, 0.0, 3.0]),
        view="workspace",
        **options,
    )
    assert app.render_main(opts) == 0
    return imageio.imread(opts.out)[..., :3], np.load(opts.gbuffer), structure


def test_the_readout_is_in_the_picture(gl, monkeypatch, tmp_path):
    lines = readout_lines(READOUT)
    assert lines[:2] == [
        "waiting for daemon at tcp://127.0.0.1:5555",
        "haptic   1000 Hz   force 0.42 N (continuous 0.88 N, peak 3.30 N)",
    ]
    assert "touching A ASP 43 CB" in lines
    assert "clearance 1.40 Å   passage 3.07 Å   bottleneck 2.14 Å" in lines
    shown, _, _ = render(monkeypatch, tmp_path, "shown")
    bare, _, _ = render(monkeypatch, tmp_path, "bare", readout=False)
    changed = np.any(shown != bare, axis=2)
    rows, cols = np.nonzero(changed)
    assert rows.size > 0, "the readout is not in the picture"
    # Only the box changed: the live lines without the status line the run waited past
    height, width = text_image(lines[1:])[..., 0].shape
    assert rows.min() >= MARGIN and rows.max() < MARGIN + height, (rows.min(), rows.max())
    assert cols.min() >= MARGIN and cols.max() < MARGIN + width, (cols.min(), cols.max())
    box = (slice(MARGIN, MARGIN + height), slice(MARGIN, MARGIN + width))
    # white letters over a box darker than what it covers
    assert (shown[box].min(axis=2) > 230).sum() > 500
    assert np.median(shown[box]) < np.median(bare[box])


def projected_inside(g, points: np.ndarray) -> np.ndarray:
    """Which points the frame's camera puts inside the picture (its view and projection)."""
    clip = np.c_[points, np.ones(len(points))] @ (g["proj"] @ g["view"]).T
    ndc = clip[:, :3] / clip[:, 3:]
    return (clip[:, 3] > 0) & np.all(np.abs(ndc[:, :2]) <= 1.0, axis=1)


def test_overview_first_shows_the_cube_on_the_whole_molecule(gl, monkeypatch, tmp_path):
    """The workspace view sees the cube face on, the molecule behind it, where the trace is
    hidden (it never covers the cube); the overview sees the cube on the whole trace."""
    _, workspace, structure = render(monkeypatch, tmp_path, "workspace", readout=False)
    _, overview, _ = render(monkeypatch, tmp_path, "overview", overview_first_s=60.0, readout=False)
    cube_center, half = overview["nav_cube"][:3], overview["nav_cube"][3]
    corners = cube_center + half * np.array(
        [[x, y, z] for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)], dtype=float
    )
    trace = structure.positions[np.concatenate(structure.backbone)]
    for g in (workspace, overview):
        assert projected_inside(g, corners).all()  # the cube is in the picture either way
    inside = projected_inside(overview, trace)
    assert inside.all(), f"{(~inside).sum()} of {inside.size} trace atoms outside the overview"
    shown = [int((g["kind"] == KIND_BACKBONE).sum()) for g in (workspace, overview)]
    assert shown[1] > 3 * shown[0], f"trace pixels: workspace view {shown[0]}, overview {shown[1]}"
