"""Where the renderer's structure and live state come from.

A source is polled once per frame: `poll()` takes in what has arrived (never blocking),
`take_new_structure()` hands out a structure once when one (re)appears, `apply(scene)`
writes the live state (probe, cube, planes, lights) into the SceneState, and `readout()`
says what the window's text shows. `StaticSource` is a file (nothing changes);
follow/daemon_source.py's DaemonSource follows a running daemon. The base class's methods
are the defaults of a source that has nothing live.
"""

from __future__ import annotations

import abc
from dataclasses import dataclass

from sasprobe.molecule import Structure


@dataclass
class Readout:
    """What the on-screen text shows besides fps."""

    status: str = ""  # e.g. 'waiting for daemon at tcp://...'
    haptic_hz: float | None = None
    force_n: float | None = None
    dropped: int = 0  # malformed messages dropped
    touched: str | None = None  # the touched atom: chain, residue name, number, atom name
    continuous_force_n: float | None = None  # the device's ratings, for the force line
    peak_force_n: float | None = None
    clutched: bool = False
    drifting: bool = False
    clearance_A: float | None = None  # at the probe centre (render/follow/live_clearance.py)
    passage_A: float | None = None  # widest sphere across the probe's path; None: open
    bottleneck_A: float | None = None  # the narrowest passage in contact so far
    note: str = ""  # a passing message, e.g. the answer to a dropped mark


class RenderSource(abc.ABC):
    follows_daemon = False  # True: the view's turn, the clutch and recentre go to a daemon

    @abc.abstractmethod
    def take_new_structure(self) -> Structure | None: ...

    def wait_ready(self) -> None:
        """Headless start: block until there is something to draw (or fail in one line)."""

    def poll(self) -> None:
        """Take in what has arrived, without blocking."""

    def apply(self, scene) -> None:
        """Write the live state into the scene."""

    def readout(self) -> Readout:
        return Readout()

    def drop_mark(self) -> None:
        """The window's Enter key: mark the probe's position (only a daemon keeps marks)."""

    def show_live_clearance(self) -> None:
        """A window shows the readout: work out the room at the probe from now on
        (render/follow/live_clearance.py; headless runs never pay for it)."""

    def stream_report(self) -> dict | None:
        """What arrived and what was lost, for `--report`; None without a stream."""
        return None

    def preview(self):
        """(navigation cube, probe) where the live state has them before a structure is
        there to draw (render/window/waiting_view.py); (None, None) without."""
        return None, None

    def view_axes(self):
        """The workspace view's axes (3 x 3, columns) as the daemon has them; None without a
        daemon."""
        return None

    def lost_for_s(self) -> float:
        """How long a live source that was sending has been silent (0: sending, or nothing live)."""
        return 0.0

    def request(self, cmd: str, **args) -> bool:
        """Ask the daemon for something (a turn, the clutch, recentre) without waiting;
        False where there is nobody to ask."""
        return False

    def close(self) -> None:
        pass


class StaticSource(RenderSource):
    def __init__(self, structure: Structure):
        self._new: Structure | None = structure

    def take_new_structure(self) -> Structure | None:
        structure, self._new = self._new, None
        return structure
