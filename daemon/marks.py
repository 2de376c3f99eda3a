"""Marks: labelled points a user drops at the probe's position during a session.

A mark comes from the device's mark button (`mark_button`, called by the loop's button
map), from a renderer window's Enter key or from any client, both through the control
command `mark` (`drop_mark`); each is made on the loop thread at the proxy of the newest
tick. Marks are part of the scene (key `marks`, protocol/README.md) and are recorded as
`mark` control records, so a replay puts them back at the same ticks and
`replay --findings` reads them. They belong to one structure: loading another one clears
them (their positions mean nothing there).
"""

from __future__ import annotations

import logging

import numpy as np
from sasprobe.protocol.recording import json_floats
from sasprobe.protocol.scene import MAX_MARKS

from sasprobe.common.errors import UserError

log = logging.getLogger("sasprobe")


class Marks:
    """The marks on the current structure, in the order they were dropped, numbered from 1."""

    def __init__(self) -> None:
        self._marks: list[dict] = []
        self._structure: str | None = None  # sha256 of the structure they belong to

    def _follow(self, structure_sha256: str) -> None:
        if structure_sha256 != self._structure:
            self._marks.clear()
            self._structure = structure_sha256

    def drop(
        self,
        seq: int,
        position_A: np.ndarray,
        label: str | None,
        source: str,
        structure_sha256: str,
    ) -> dict:
        """A new mark at a probe position; UserError when MAX_MARKS are there already."""
        self._follow(structure_sha256)
        if len(self._marks) >= MAX_MARKS:
            raise UserError(f"a session holds at most {MAX_MARKS} marks")
        number = len(self._marks) + 1
        mark = {
            "id": number,
            "label": label or f"mark {number}",
            "position_A": json_floats(position_A),
            "seq": int(seq),
            "source": source,
        }
        self._marks.append(mark)
        return dict(mark)

    def restore(self, mark: dict) -> None:
        """A recorded mark, put back as it was (a replay: the structure is the recorded one);
        past MAX_MARKS, as live, it is not kept (a file may say anything)."""
        if len(self._marks) < MAX_MARKS:
            self._marks.append(dict(mark))

    def scene(self, structure_sha256: str) -> list[dict]:
        """The scene's `marks` for the structure in force (copies)."""
        self._follow(structure_sha256)
        return [dict(m) for m in self._marks]


def drop_mark(daemon, seq: int, label: str | None, source: str) -> dict:
    """On the loop thread: a mark at the newest proxy, recorded and in the scene."""
    output = daemon.pipeline.last_output
    if output is None:
        raise UserError("no probe position to mark yet (the device has not given a valid reading)")
    mark = daemon.marks.drop(seq, output.proxy_A, label, source, daemon.structure.sha256)
    daemon.record_control(seq, "mark", mark)
    daemon.rebuild_scene()
    return mark


def mark_button(daemon, seq: int) -> None:
    """On the loop thread: the device's mark button was pressed. A replay takes its marks
    from the recorded `mark` records instead, so none is added twice."""
    if daemon.device.recorded_session() is not None:
        return
    try:
        drop_mark(daemon, seq, None, "button")
    except UserError as exc:
        log.warning("mark button: %s", exc)
