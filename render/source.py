"""Where the renderer's structure and live state come from.

A source is polled once per frame: `poll()` takes in what has arrived (never blocking),
`take_new_structure()` hands out a structure once when one (re)appears, `apply(scene)`
writes the live state (probe, cube, planes, lights) into the SceneState, and
`readout()` says what the window's text shows. `StaticSource` is a file (nothing
changes); `render.link.DaemonLink` follows a running daemon.
"""

from __future__ import annotations

from dataclasses import dataclass

from sasprobe.molecule import Structure


@dataclass
class Readout:
    """What the on-screen text shows besides fps."""

    status: str = ""  # e.g. 'waiting for daemon at tcp://...'
    haptic_hz: float | None = None
    force_n: float | None = None
    dropped: int = 0  # malformed messages dropped


class StaticSource:
    def __init__(self, structure: Structure):
        self._new: Structure | None = structure

    def poll(self) -> None:
        pass

    def take_new_structure(self) -> Structure | None:
        structure, self._new = self._new, None
        return structure

    def apply(self, scene) -> None:
        pass

    def readout(self) -> Readout:
        return Readout()

    def close(self) -> None:
        pass
