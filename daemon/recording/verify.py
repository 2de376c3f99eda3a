"""`sasprobe replay FILE --verify`: recompute a recording's forces and compare.

The recorded inputs of every tick (device state or read error, how late the tick was)
and the recorded control commands go through a fresh HapticPipeline, exactly as the
live daemon ran them. The engine and the guard read no clock, so a deterministic
replay reproduces every force bit for bit: the expected difference is exactly zero.
Ticks the recorder dropped (queue overflow, counted in the file) break the chain: the
report says how many are missing, because forces after a gap may legitimately differ.
"""

from __future__ import annotations

import collections
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from sasprobe.daemon.haptics import HapticPipeline, SafetyGuard, build_engine, validate_settings
from sasprobe.daemon.recording.replay import apply_recorded_event, open_session, tick_state
from sasprobe.protocol.pose import FLAG_FAULT


@dataclass
class VerifyReport:
    path: str
    finished: bool  # False: the file was cut (crash) and read up to its last complete record
    ticks: int
    missing_ticks: int
    events_applied: int
    max_force_diff_n: float  # max over ticks and axes of |recomputed − recorded|
    ticks_with_force_diff: int
    first_diff_seq: int | None
    flag_mismatches: int  # ticks whose recomputed flags differ from the recorded ones
    fault_ticks: int  # recorded ticks with the fault flag (replayed too)
    structure: str

    @property
    def ok(self) -> bool:
        return self.max_force_diff_n == 0.0 and self.flag_mismatches == 0

    def as_dict(self) -> dict:
        return {**self.__dict__, "ok": self.ok}


def verify_recording(path: str | Path, progress=None) -> VerifyReport:
    """Recompute every recorded tick in one pass over the file (a block of ticks at a time)."""
    session = open_session(path)
    limits = session.device_limits()
    structure = session.structure(session.start["structure_sha256"])
    settings = validate_settings(session.settings, limits)
    pipeline = HapticPipeline(build_engine(structure, limits, settings), SafetyGuard(limits))
    pending: collections.deque = collections.deque()  # control records not yet due
    applied = ticks = diff_ticks = flag_mismatches = fault_ticks = 0
    max_diff = 0.0
    first_diff = first_seq = last_seq = None
    for entry in session.stream():
        if isinstance(entry, dict):
            pending.append(entry)
            continue
        seqs = entry.seq
        late = entry.device["late_periods"].tolist()
        forces = np.empty((len(entry), 3))
        flags = np.empty(len(entry), dtype=np.int64)
        for row, seq in enumerate(seqs.tolist()):
            while pending and pending[0]["seq"] <= seq:
                structure, settings = apply_recorded_event(
                    pending.popleft(), pipeline, structure, settings, limits, session.structure
                )
                applied += 1
            state, error = tick_state(entry, row)
            result = pipeline.step(state, error, late[row])
            forces[row] = result.force_n
            flags[row] = result.flags
        recorded_flags = entry.pose["flags"]
        diff = np.max(np.abs(forces - entry.pose["force_N"]), axis=1)
        differ = ~(diff == 0.0)  # NaN differs too
        if differ.any():
            diff_ticks += int(np.count_nonzero(differ))
            first_diff = int(seqs[np.argmax(differ)]) if first_diff is None else first_diff
            worst = diff[differ]
            max_diff = max(max_diff, float(np.max(np.where(np.isfinite(worst), worst, np.inf))))
        flag_mismatches += int(np.count_nonzero(flags != recorded_flags))
        ticks += len(seqs)
        fault_ticks += int(np.count_nonzero(recorded_flags & FLAG_FAULT))
        first_seq = int(seqs[0]) if first_seq is None else first_seq
        last_seq = int(seqs[-1])
        if progress is not None:
            progress(len(seqs))
    return VerifyReport(
        path=str(path),
        finished=session.finished,
        ticks=ticks,
        missing_ticks=(last_seq - first_seq + 1 - ticks) if ticks else 0,
        events_applied=applied,
        max_force_diff_n=max_diff,
        ticks_with_force_diff=diff_ticks,
        first_diff_seq=first_diff,
        flag_mismatches=flag_mismatches,
        fault_ticks=fault_ticks,
        structure=structure.name,
    )
