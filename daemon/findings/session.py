"""What the findings read from a recording: the probe's track, the marks, the structure.

Everything comes from the file alone (the structure is its attachment), through the
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


@dataclass
class Track:
    """The probe, tick by tick, from the first recorded tick (t = 0) on."""

    structure: Structure
    structure_file: bytes  # the attached file, exactly as the daemon read it
    probe_radius_A: float  # the session's probe radius (its start settings)
    rate_hz: float
    t_s: np.ndarray  # (N,) seconds since the first tick (tick count / rate)
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
        notes.append("the recording was cut (its daemon was killed): read up to its last complete record")
    if session.missing_ticks:
        notes.append(f"{session.missing_ticks} ticks were dropped while recording")
    end = session.n_ticks
    marks = []
    for event in session.events:
        cmd, args = event.get("cmd"), event.get("args", {})
        tick = int(np.searchsorted(session.seq, event["seq"]))
        if cmd == "load" and args.get("sha256") != sha:
            end = min(end, tick)
            notes.append(f"the session loaded {args.get('name', 'another structure')} at tick {event['seq']}: "
                         f"the findings cover {structure.name} up to there")
            break
        if cmd == "set" and "probe_radius_A" in args and float(args["probe_radius_A"]) != radius:
            notes.append(f"the probe radius was set to {float(args['probe_radius_A']):g} Å at tick {event['seq']}; "
                         f"the verdicts use the session's starting radius, {radius:g} Å")
        if cmd == "mark":
            marks.append({**args, "t_s": (event["seq"] - int(session.seq[0])) / rate})
    flags = session.flags[:end]
    return Track(
        structure=structure,
        structure_file=session.structures[sha][1],
        probe_radius_A=radius,
        rate_hz=rate,
        t_s=(session.seq[:end] - session.seq[0]) / rate,
        seq=session.seq[:end],
        proxy_A=session.proxy_A[:end],
        force_N=np.linalg.norm(np.nan_to_num(session.force_n[:end]), axis=1),
        contact=((flags & FLAG_CONTACT) != 0) & ((flags & FLAG_FAULT) == 0),
        touched_atom=session.touched_atom[:end],
        marks=marks,
        notes=notes,
        finished=session.finished,
        source=str(path),
    )
