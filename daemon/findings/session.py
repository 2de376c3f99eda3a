"""What the findings read from a recording: the probe's track, the marks, the structure.

Time is the device's (when each state was read: the host's clock for a real arm, the
simulated clock for the simulated one); a tick whose read failed gets the time between
its neighbours. Everything comes from the file alone (the structure is its attachment), through the
same reader the replay device uses; a file cut by SIGKILL is read up to its last
complete record. A session that loaded another structure is analysed up to that load
(the path after it runs through other atoms); the findings say so.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from sasprobe.daemon.recording.replay import load_session
from sasprobe.molecule import DEFAULT_PROBE_RADIUS, Structure
from sasprobe.protocol.pose import FLAG_CONTACT, FLAG_FAULT

MAX_TICK_S = 0.05  # a longer gap between ticks (a stall, dropped records) is not contact time


@dataclass
class Track:
    """The probe, tick by tick, from the first recorded tick (t = 0) on."""

    structure: Structure
    structure_file: bytes  # the attached file, exactly as the daemon read it
    probe_radius_A: float  # the session's probe radius (its start settings)
    rate_hz: float
    t_s: np.ndarray  # (N,) device time since the first tick, s
    # (N,) the time each tick stands for (since the one before, at most MAX_TICK_S)
    dt_s: np.ndarray
    seq: np.ndarray  # (N,)
    proxy_A: np.ndarray  # (N, 3) probe centre
    force_N: np.ndarray  # (N,) |force| written to the device
    contact: np.ndarray  # (N,) bool: touching the SAS (fault ticks never count)
    touched_atom: np.ndarray  # (N,) the atom the daemon reported touched, -1 for none
    marks: list[dict] = field(default_factory=list)  # recorded marks, each with its t_s
    notes: list[str] = field(default_factory=list)
    finished: bool = True  # False: the recording was cut (its daemon was killed)
    source: str = ""

    @property
    def n_ticks(self) -> int:
        return int(self.seq.size)

    @property
    def duration_s(self) -> float:
        return float(self.t_s[-1]) if self.n_ticks else 0.0


def read_track(path: str | Path) -> Track:
    """The track of a recording (finished or cut); a UserError when it is not a usable one."""
    session = load_session(path)
    sha = session.start["structure_sha256"]
    structure = session.structure(sha)
    rate = session.rate_hz
    radius = float(session.settings.get("probe_radius_A", DEFAULT_PROBE_RADIUS))
    notes = []
    if not session.finished:
        notes.append(
            "the recording was cut (its daemon was killed): read up to its last complete record"
        )
    if session.missing_ticks:
        notes.append(f"{session.missing_ticks} ticks were dropped while recording")
    end = session.n_ticks
    events = []
    for event in session.events:
        cmd, args = event.get("cmd"), event.get("args", {})
        if cmd == "load" and args.get("sha256") != sha:
            end = min(end, int(np.searchsorted(session.seq, event["seq"])))
            notes.append(
                f"the session loaded {args.get('name', 'another structure')} at tick "
                f"{event['seq']}: the findings cover {structure.name} up to there"
            )
            break
        if cmd == "set" and "probe_radius_A" in args and float(args["probe_radius_A"]) != radius:
            notes.append(
                f"the probe radius was set to {float(args['probe_radius_A']):g} Å at tick "
                f"{event['seq']}; the verdicts use the session's starting radius, {radius:g} Å"
            )
        events.append(event)
    end = max(end, 1)
    seq, flags = session.seq[:end], session.flags[:end]
    stamped = session.has_state[:end] & (session.t_ns[:end] > 0)
    t_ns = (
        np.interp(seq, seq[stamped], session.t_ns[:end][stamped])
        if stamped.any()
        else (seq - seq[0]) * 1e9 / rate
    )
    t_s = (t_ns - t_ns[0]) / 1e9
    dt_s = np.clip(np.diff(t_s, prepend=t_s[0] - 1.0 / rate), 0.0, MAX_TICK_S)
    marks = [
        {**e["args"], "t_s": float(t_s[min(int(np.searchsorted(seq, e["seq"])), end - 1)])}
        for e in events
        if e.get("cmd") == "mark"
    ]
    return Track(
        structure=structure,
        structure_file=session.structures[sha][1],
        probe_radius_A=radius,
        rate_hz=rate,
        t_s=t_s,
        dt_s=dt_s,
        seq=seq,
        proxy_A=session.proxy_A[:end],
        force_N=np.linalg.norm(np.nan_to_num(session.force_n[:end]), axis=1),
        contact=((flags & FLAG_CONTACT) != 0) & ((flags & FLAG_FAULT) == 0),
        touched_atom=session.touched_atom[:end],
        marks=marks,
        notes=notes,
        finished=session.finished,
        source=str(path),
    )
