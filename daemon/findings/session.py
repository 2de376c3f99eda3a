"""What the findings read from a recording: the probe's track, the marks, the structure.

A Track is the session's header (the structure, the probe radius, the rate) and its ticks
as a stream of TrackBlocks; each call of `blocks()` reads the recording again, so an
analysis holds one block at a time and a session of any length fits in memory.

Time is the device's (when each state was read: the host's clock for a real arm, the
simulated clock for the simulated one); a tick whose read failed gets the time
interpolated by tick number between the stamped ticks around it (the first stamped
tick's time before it, the last one's after it). The ticks of such a run wait for the
next stamped tick, MAX_UNSTAMPED_TICKS at most: a longer run (an arm gone for minutes)
takes the last stamped time advanced one period a tick instead. Everything comes from
the file alone (the structure is its attachment), through the same reader the replay
device uses; a file cut by SIGKILL is read up to its last complete record. A session
that loaded another structure is analysed up to that load (the path after it runs
through other atoms); the findings say so.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from sasprobe.daemon.recording.replay import ReplaySession, open_session
from sasprobe.molecule import DEFAULT_PROBE_RADIUS, Structure
from sasprobe.protocol.pose import FLAG_CONTACT, FLAG_FAULT
from sasprobe.protocol.ticks import TickBlock

MAX_TICK_S = 0.05  # a longer gap between ticks (a stall, dropped records) is not contact time
MAX_UNSTAMPED_TICKS = 1 << 16  # ticks without device time that wait for the next stamped one


@dataclass
class TrackBlock:
    """Consecutive ticks of a track, from track index `first` on."""

    first: int
    seq: np.ndarray  # (n,)
    t_s: np.ndarray  # (n,) device time since the first tick, s
    dt_s: (
        np.ndarray
    )  # (n,) the time each tick stands for (since the one before, at most MAX_TICK_S)
    proxy_A: np.ndarray  # (n, 3) probe centre
    force_N: np.ndarray  # (n,) |force| written to the device
    contact: np.ndarray  # (n,) bool: touching the SAS (fault ticks never count)
    touched_atom: np.ndarray  # (n,) the atom the daemon reported touched, -1 for none
    marked: list[int] = field(default_factory=list)  # rows where a mark was dropped

    def __len__(self) -> int:
        return int(self.seq.size)


@dataclass
class Track:
    """The probe, tick by tick, from the first recorded tick (t = 0) on: the session's header
    and its ticks as a stream (`blocks()`). `marks` (each with its t_s), `notes`, `n_ticks`
    and `duration_s` are complete once a pass over `blocks()` has ended."""

    structure: Structure
    structure_file: bytes  # the attached file, exactly as the daemon read it
    probe_radius_A: float  # the session's probe radius (its start settings)
    rate_hz: float
    read_blocks: Callable[[Track], Iterator[TrackBlock]]
    finished: bool = True  # False: the recording was cut (its daemon was killed)
    source: str = ""
    marks: list[dict] = field(default_factory=list)
    notes: list[str] = field(default_factory=list)
    n_ticks: int = 0
    duration_s: float = 0.0

    def blocks(self) -> Iterator[TrackBlock]:
        return self.read_blocks(self)


def track_of_arrays(
    structure: Structure,
    structure_file: bytes,
    probe_radius_A: float,
    rate_hz: float,
    t_s: np.ndarray,
    dt_s: np.ndarray,
    seq: np.ndarray,
    proxy_A: np.ndarray,
    force_N: np.ndarray,
    contact: np.ndarray,
    touched_atom: np.ndarray,
    marks: list[dict] | None = None,
) -> Track:
    """A track of arrays in memory (one block), its marks given with their seq and t_s."""
    marks = list(marks or [])
    n = int(np.asarray(seq).size)

    def read_blocks(track: Track) -> Iterator[TrackBlock]:
        track.n_ticks, track.duration_s = n, float(t_s[-1]) if n else 0.0
        marked = [min(int(np.searchsorted(seq, m["seq"])), n - 1) for m in marks]
        yield TrackBlock(0, seq, t_s, dt_s, proxy_A, force_N, contact, touched_atom, marked)

    return Track(structure, structure_file, probe_radius_A, rate_hz, read_blocks, marks=list(marks))


def read_track(path: str | Path) -> Track:
    """The track of a recording (finished or cut); a UserError when it is not a usable one."""
    session = open_session(path)
    sha = session.start["structure_sha256"]
    return Track(
        structure=session.structure(sha),
        structure_file=session.structures[sha][1],
        probe_radius_A=float(session.settings.get("probe_radius_A", DEFAULT_PROBE_RADIUS)),
        rate_hz=session.rate_hz,
        read_blocks=lambda track: _recorded_blocks(track, session),
        finished=session.finished,
        source=str(path),
    )


class _Clock:
    """Device time for each tick, a block at a time, and the ticks kept waiting for it."""

    def __init__(self, rate_hz: float) -> None:
        self.rate_hz = rate_hz
        self.last: tuple[int, float] | None = None  # the last stamped tick's (seq, t_ns)
        self.waiting: list[TickBlock] = []  # ticks after it, none stamped

    def take(self, block: TickBlock | None) -> Iterator[tuple[TickBlock, np.ndarray]]:
        """Ticks whose time is known now, with their device time (ns); None: the end."""
        if block is not None:
            self.waiting.append(block)
            if not _stamped(block).any():
                if sum(len(b) for b in self.waiting) > MAX_UNSTAMPED_TICKS:
                    yield from self._advance()
                return
        if not self.waiting:
            return
        ticks = TickBlock.join(self.waiting)
        self.waiting = []
        seq = ticks.seq
        stamped = _stamped(ticks)
        if not stamped.any():  # the end, after a run without device time
            if self.last is None:  # no device time at all: the recorded rate
                yield ticks, (seq - seq[0]) * 1e9 / self.rate_hz
            else:
                yield ticks, np.full(len(ticks), self.last[1])
            return
        cut = int(np.flatnonzero(stamped)[-1]) + 1 if block is not None else len(ticks)
        xp, fp = seq[stamped], ticks.device["t_ns"][stamped]
        if self.last is not None:
            xp, fp = np.concatenate(([self.last[0]], xp)), np.concatenate(([self.last[1]], fp))
        yield ticks.rows(0, cut), np.interp(seq[:cut], xp, fp)
        self.last = (int(xp[-1]), float(fp[-1]))
        if cut < len(ticks):
            self.waiting = [ticks.rows(cut, len(ticks))]

    def _advance(self) -> Iterator[tuple[TickBlock, np.ndarray]]:
        """A run too long to wait for: its time runs on from the last stamped tick."""
        ticks = TickBlock.join(self.waiting)
        self.waiting = []
        seq = ticks.seq
        if self.last is None:
            self.last = (int(seq[0]), 0.0)
        t_ns = self.last[1] + (seq - self.last[0]) * 1e9 / self.rate_hz
        self.last = (int(seq[-1]), float(t_ns[-1]))
        yield ticks, t_ns


def _stamped(block: TickBlock) -> np.ndarray:
    return block.has_state & (block.device["t_ns"] > 0)


def _recorded_blocks(track: Track, session: ReplaySession) -> Iterator[TrackBlock]:
    """One pass over the recording: the track's blocks up to a load of another structure, and
    its marks and notes on the way."""
    sha = session.start["structure_sha256"]
    radius, rate = track.probe_radius_A, track.rate_hz
    notes: list[str] = []
    marks: list[dict] = []
    unplaced: list[dict] = []  # marks waiting for the first tick at or after theirs
    clock = _Clock(rate)
    t0 = previous_t = None
    index = 0
    first_seq = last_seq = None
    recorded = 0  # ticks in the file, the ones after a cut included
    cut = False

    def track_blocks(ticks: TickBlock, t_ns: np.ndarray) -> Iterator[TrackBlock]:
        nonlocal t0, previous_t, index
        if t0 is None:
            t0 = t_ns[0]
            previous_t = (t_ns[0] - t0) / 1e9 - 1.0 / rate
        t_s = (t_ns - t0) / 1e9
        dt_s = np.clip(np.diff(t_s, prepend=previous_t), 0.0, MAX_TICK_S)
        previous_t = t_s[-1]
        seq, flags = ticks.seq, ticks.pose["flags"]
        marked = []
        while unplaced and unplaced[0]["seq"] <= seq[-1]:
            row = int(np.searchsorted(seq, unplaced[0]["seq"]))
            marks.append({**unplaced.pop(0), "t_s": float(t_s[row])})
            marked.append(row)
        yield TrackBlock(
            first=index,
            seq=seq,
            t_s=t_s,
            dt_s=dt_s,
            proxy_A=np.array(ticks.pose["proxy_A"]),
            force_N=np.linalg.norm(np.nan_to_num(ticks.pose["force_N"]), axis=1),
            contact=((flags & FLAG_CONTACT) != 0) & ((flags & FLAG_FAULT) == 0),
            touched_atom=ticks.pose["touched_atom"].astype(np.int64),
            marked=marked,
        )
        index += len(ticks)

    for entry in session.stream():
        if isinstance(entry, TickBlock):
            recorded += len(entry)
            first_seq = int(entry.pose["seq"][0]) if first_seq is None else first_seq
            last_seq = int(entry.pose["seq"][-1])
            if cut and index + sum(len(b) for b in clock.waiting):
                continue  # after a load of another structure: counted, not analysed
            if cut:  # a load before any tick: the first tick is analysed all the same
                entry = entry.rows(0, 1)
            for ticks, t_ns in clock.take(entry):
                yield from track_blocks(ticks, t_ns)
            continue
        if cut:
            continue
        cmd, args = entry.get("cmd"), entry.get("args", {})
        if cmd == "load" and args.get("sha256") != sha:
            cut = True
            notes.append(
                f"the session loaded {args.get('name', 'another structure')} at tick "
                f"{entry['seq']}: the findings cover {track.structure.name} up to there"
            )
        elif cmd == "set" and "probe_radius_A" in args and float(args["probe_radius_A"]) != radius:
            notes.append(
                f"the probe radius was set to {float(args['probe_radius_A']):g} Å at tick "
                f"{entry['seq']}; the verdicts use the session's starting radius, {radius:g} Å"
            )
        elif cmd == "mark":
            unplaced.append({**args})
    for ticks, t_ns in clock.take(None):
        yield from track_blocks(ticks, t_ns)
    if unplaced and index:  # marks after the last tick: placed at it
        marks.extend({**m, "t_s": float(previous_t)} for m in unplaced)
        unplaced.clear()
    missing = (last_seq - first_seq + 1 - recorded) if recorded else 0
    track.notes = [
        *(
            ["the recording was cut (its daemon was killed): read up to its last complete record"]
            if not session.finished
            else []
        ),
        *([f"{missing} ticks were dropped while recording"] if missing else []),
        *notes,
    ]
    track.marks = marks
    track.n_ticks = index
    track.duration_s = float(previous_t) if index else 0.0
