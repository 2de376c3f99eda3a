"""The window's live clearance readout: at the probe, and the narrowest passage so far.

From the poses a renderer receives (it never asks the daemon): the clearance at the probe
centre and the passage radius across its direction of travel (molecule/clearance.py), and
the running bottleneck — the narrowest passage while in contact, counted by the rule
`sasprobe replay --findings` uses (a passage must bound the path over MIN_RUN_A). The
probe is evaluated each time it has moved SPACING_A, at most MAX_PER_POLL times a frame
(a slow frame skips points between them), so the readout costs a few milliseconds a frame
and its bottleneck follows the findings' without being a copy of them.
It starts again when the structure or the probe radius changes.
"""

from __future__ import annotations

import math

import numpy as np
from sasprobe.molecule.clearance import MIN_RUN_A, ClearanceField
from sasprobe.protocol.pose import FLAG_CONTACT, FLAG_FAULT

SPACING_A = 0.25  # the findings' path spacing
MAX_PER_POLL = 6


class LiveClearance:
    def __init__(self) -> None:
        self._field: ClearanceField | None = None
        self._key: tuple | None = None
        self.reset()

    def reset(self) -> None:
        self.clearance_A: float | None = None
        self.passage_A: float | None = None  # None: open (no passage bounds the probe here)
        self.bottleneck_A: float | None = None
        self._last: np.ndarray | None = None  # the last pose position taken in
        self._evaluated: np.ndarray | None = None  # the last position evaluated
        # (travel, narrowest contact passage) of a bounded run.
        self._run: tuple[float, float | None] | None = None

    def update(self, structure, probe_radius_A: float, poses: list) -> None:
        """Take in the poses of one poll (oldest first)."""
        key = (id(structure), float(probe_radius_A))
        if key != self._key:
            self._field = ClearanceField.of(structure)
            self._key = key
            self.reset()
        picked = []  # (position, the position taken in before it, in contact)
        for pose in poses:
            p = np.asarray(pose.proxy_A, dtype=np.float64)
            if pose.has(FLAG_FAULT) or (
                self._last is not None and math.dist(p, self._last) < SPACING_A
            ):
                continue
            picked.append((p, self._last, pose.has(FLAG_CONTACT)))
            self._last = p
        if len(picked) > MAX_PER_POLL:
            picked = [picked[int(k)] for k in np.linspace(0, len(picked) - 1, MAX_PER_POLL).round()]
        for p, previous, contact in picked:
            self._evaluate(p, previous, contact)

    def _evaluate(self, p: np.ndarray, previous: np.ndarray | None, contact: bool) -> None:
        self.clearance_A = float(self._field.clearance(p)[0][0])
        step = 0.0 if self._evaluated is None else math.dist(p, self._evaluated)
        self._evaluated = p
        if previous is None:  # no direction of travel yet
            return
        passage = self._field.passage(p, p - previous)
        self.passage_A = None if passage.open else passage.radius_A
        if passage.open:
            self._run = None
            return
        travel, narrowest = (
            (0.0, None) if self._run is None else (self._run[0] + step, self._run[1])
        )
        if contact:
            narrowest = passage.radius_A if narrowest is None else min(narrowest, passage.radius_A)
        self._run = (travel, narrowest)
        if narrowest is not None and travel >= MIN_RUN_A:
            self.bottleneck_A = (
                narrowest if self.bottleneck_A is None else min(self.bottleneck_A, narrowest)
            )
