"""`sasprobe replay FILE --verify`: recompute a recording's forces and compare.

The recorded inputs of every tick (device state or read error, how late the tick was)
and the recorded control commands go through a fresh HapticPipeline, exactly as the
live daemon ran them. The engine and the guard read no clock, so a deterministic
replay reproduces every force bit for bit: the expected difference is exactly zero.
Ticks the recorder dropped (queue overflow, counted in the file) break the chain: the
report says how many are missing, because forces after a gap may legitimately differ.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
from sasprobe.daemon.haptics import HapticPipeline, SafetyGuard, build_engine, validate_settings
from sasprobe.daemon.recording.replay import apply_recorded_event, load_session
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
    session = load_session(path)
    limits = session.device_limits()
    structure = session.structure(session.start["structure_sha256"])
    settings = validate_settings(session.settings, limits)
    pipeline = HapticPipeline(build_engine(structure, limits, settings), SafetyGuard(limits))
    events = session.events
    next_event = 0
    max_diff = 0.0
    diff_ticks = 0
    first_diff = None
    flag_mismatches = 0
    for i in range(session.n_ticks):
        seq = int(session.seq[i])
        while next_event < len(events) and events[next_event]["seq"] <= seq:
            structure, settings = apply_recorded_event(
                events[next_event], pipeline, structure, settings, limits, session.structure
            )
            next_event += 1
        state, error = session.state(i)
        result = pipeline.step(state, error, float(session.late_periods[i]))
        diff = float(np.max(np.abs(result.force_n - session.force_n[i])))
        if diff > 0.0 or not np.isfinite(diff):
            diff_ticks += 1
            first_diff = seq if first_diff is None else first_diff
            max_diff = max(max_diff, diff if np.isfinite(diff) else np.inf)
        if result.flags != int(session.flags[i]):
            flag_mismatches += 1
        if progress is not None:
            progress(1)
    return VerifyReport(
        path=str(path),
        finished=session.finished,
        ticks=session.n_ticks,
        missing_ticks=session.missing_ticks,
        events_applied=next_event,
        max_force_diff_n=max_diff,
        ticks_with_force_diff=diff_ticks,
        first_diff_seq=first_diff,
        flag_mismatches=flag_mismatches,
        fault_ticks=int(np.count_nonzero(session.flags & FLAG_FAULT)),
        structure=structure.name,
    )
