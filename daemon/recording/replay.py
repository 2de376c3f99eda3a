"""`--device replay:FILE`: a recorded session's device states, played back as a device.

Each read() returns the next recorded device state (or raises DeviceFault where the
recording has a failed read), so the daemon recomputes forces through the same
pipeline; it also hands the daemon the recorded control commands and how late each
tick was, so settings changes and timing faults recur where they happened. The daemon
paces the replay at the recorded rate times --speed (`max`: as fast as it can); after
the last state read() raises ReplayFinished (an EOFError). The whole device channel is
loaded when the device is made, so the loop never waits on the disk.

The replay device reads the daemon's own recordings, so it lives here rather than in
devices/; the daemon registers its scheme (replay_scheme.py) with the device registry.
`apply_recorded_event` is how both a replaying daemon and `replay --verify` repeat a
recorded control command.
"""

from __future__ import annotations

import os
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from sasprobe.daemon.haptics import HapticPipeline, build_engine, validate_settings
from sasprobe.daemon.haptics.settings import needs_rebuild, split_changes
from sasprobe.devices.base import (
    DeviceFault,
    DeviceInfo,
    DeviceLimits,
    DeviceOpenError,
    DeviceState,
    HapticDevice,
)
from sasprobe.devices.workspace.mapping import validate_rotation
from sasprobe.protocol.recording import RecordingError, iter_items, scan

from sasprobe.common.files import open_regular


class ReplayFinished(EOFError):
    """The recording has no more device states."""


@dataclass
class ReplaySession:
    """A recording's replay input and its recorded output, as compact arrays."""

    path: Path
    finished: bool  # the recorder closed the file (False: recovered after a crash)
    start: dict  # the `start` control record's args: settings, structure, device, rate
    structures: dict  # sha256 -> (name, bytes)
    seq: np.ndarray  # (N,) tick numbers
    t_ns: np.ndarray  # (N,)
    position_mm: np.ndarray  # (N, 3), NaN where the recording had non-finite values
    orientation: np.ndarray  # (N, 4)
    velocity_mm_s: np.ndarray  # (N, 3)
    buttons: np.ndarray  # (N,)
    calibrated: np.ndarray  # (N,) bool
    has_state: np.ndarray  # (N,) bool: False when the read failed before returning a state
    late_periods: np.ndarray  # (N,)
    errors: dict  # tick index -> read error
    force_n: np.ndarray  # (N, 3) the recorded (published) force
    flags: np.ndarray  # (N,)
    proxy_A: np.ndarray  # (N, 3) the recorded probe centre
    touched_atom: np.ndarray  # (N,) the recorded touched atom, -1 for none
    events: list = field(default_factory=list)  # control records after `start`, in order

    @property
    def n_ticks(self) -> int:
        return int(self.seq.size)

    @property
    def missing_ticks(self) -> int:
        return int(self.seq[-1] - self.seq[0] + 1 - self.seq.size) if self.seq.size else 0

    @property
    def rate_hz(self) -> float:
        return float(self.start.get("rate_hz") or self.start["device"]["limits"]["nominal_rate_hz"])

    @property
    def settings(self) -> dict:
        return dict(self.start["settings"])

    @property
    def keep_water(self) -> bool:
        return bool(self.start.get("keep_water", False))

    @property
    def structure_name(self) -> str:
        return self.structures[self.start["structure_sha256"]][0]

    @property
    def structure_bytes(self) -> bytes:
        return self.structures[self.start["structure_sha256"]][1]

    def structure(self, sha256: str, keep_water: bool | None = None):
        from sasprobe.molecule import parse_structure

        if sha256 not in self.structures:
            raise DeviceOpenError(
                f"{self.path}: structure {sha256[:12]} is not attached to the recording"
            )
        name, data = self.structures[sha256]
        return parse_structure(
            data,
            name=name,
            source=f"{self.path}:{name}",
            keep_water=self.keep_water if keep_water is None else keep_water,
        )

    def device_limits(self) -> DeviceLimits:
        lim = dict(self.start["device"]["limits"])
        lim["workspace_min_mm"] = tuple(lim["workspace_min_mm"])
        lim["workspace_max_mm"] = tuple(lim["workspace_max_mm"])
        return DeviceLimits(**lim)

    def state(self, i: int) -> tuple[DeviceState | None, str | None]:
        """Tick i's device state (None when the read failed) and its read error."""
        state = None
        if self.has_state[i]:
            state = DeviceState(
                t_ns=int(self.t_ns[i]),
                position_mm=self.position_mm[i].copy(),
                orientation=self.orientation[i].copy(),
                velocity_mm_s=self.velocity_mm_s[i].copy(),
                buttons=int(self.buttons[i]),
                calibrated=bool(self.calibrated[i]),
            )
        return state, self.errors.get(i)


def _vector(values, n: int) -> list[float]:
    if values is None:
        return [np.nan] * n
    return [np.nan if v is None else float(v) for v in values]


def load_session(path: str | Path) -> ReplaySession:
    """Read a recording (finished or recovered) into a ReplaySession; DeviceOpenError if
    unusable."""
    path = Path(path)
    try:
        finished = scan(path).finished
        items = list(iter_items(path))
    except RecordingError as exc:
        raise DeviceOpenError(str(exc)) from None
    structures: dict = {}
    start: dict | None = None
    events: list = []
    ticks: dict[int, dict] = {}
    poses: dict[int, dict] = {}
    for item in items:
        if item.topic == "attachment":
            structures[item.data["sha256"]] = (item.data["name"], item.raw)
        elif item.topic == "control":
            if item.data.get("cmd") == "start" and start is None:
                start = item.data["args"]
            elif start is not None:
                events.append(item.data)
        elif item.topic == "device" and start is not None:
            ticks[item.data["seq"]] = item.data
        elif item.topic == "pose" and start is not None:
            poses[item.data["seq"]] = item.data
    if start is None:
        raise DeviceOpenError(f"{path}: not a sasprobe recording (no start record)")
    if start.get("structure_sha256") not in structures:
        raise DeviceOpenError(f"{path}: the recorded structure is not attached")
    seqs = sorted(s for s in ticks if s in poses)  # a tick counts once both halves were written
    if not seqs:
        raise DeviceOpenError(f"{path}: no recorded ticks")
    rows = [ticks[s] for s in seqs]
    errors = {i: r["error"] for i, r in enumerate(rows) if r.get("error") is not None}
    return ReplaySession(
        path=path,
        finished=finished,
        start=start,
        structures=structures,
        seq=np.array(seqs, dtype=np.int64),
        t_ns=np.array([r.get("t_ns") or 0 for r in rows], dtype=np.int64),
        position_mm=np.array([_vector(r.get("position_mm"), 3) for r in rows]),
        orientation=np.array([_vector(r.get("orientation"), 4) for r in rows]),
        velocity_mm_s=np.array([_vector(r.get("velocity_mm_s"), 3) for r in rows]),
        buttons=np.array([r.get("buttons") or 0 for r in rows], dtype=np.int64),
        calibrated=np.array([r.get("calibrated", True) is not False for r in rows], dtype=bool),
        has_state=np.array(
            [r.get("t_ns") is not None for r in rows], dtype=bool
        ),  # null or absent: no state
        late_periods=np.array([r.get("late_periods", 0.0) for r in rows]),
        errors=errors,
        force_n=np.array([_vector(poses[s]["force_N"], 3) for s in seqs]),
        flags=np.array([poses[s]["flags"] for s in seqs], dtype=np.int64),
        proxy_A=np.array([_vector(poses[s]["proxy_A"], 3) for s in seqs]),
        touched_atom=np.array([poses[s]["touched_atom"] for s in seqs], dtype=np.int64),
        events=events,
    )


class ReplayDevice(HapticDevice):
    def __init__(self, path: str, speed: float | None = 1.0) -> None:
        self.path = Path(path)
        self.speed = speed
        self.session = load_session(self.path)
        self._index = 0
        self._event_index = 0
        self.last_force_n = np.zeros(3)
        recorded = self.session.start["device"]
        self._info = DeviceInfo(
            kind="replay",
            model=f"replay of {recorded.get('model', 'a device')}",
            limits=self.session.device_limits(),
            details={
                "file": self.path.name,
                "ticks": self.session.n_ticks,
                "recorded_kind": recorded.get("kind"),
                "speed": "max" if speed is None else speed,
            },
        )

    @property
    def info(self) -> DeviceInfo:
        return self._info

    def open(self) -> None:
        self._index = 0
        self._event_index = 0

    def close(self) -> None:
        self.last_force_n = np.zeros(3)

    def reconnect(self) -> None:
        """A file does not go away: the recorded reconnects come back as recorded events,
        so the daemon's own attempts (after a recorded read failure) add nothing."""
        raise DeviceFault("a replay repeats the recorded reconnects")

    def recorded_session(self) -> ReplaySession:
        return self.session

    def read(self) -> DeviceState:
        if self._index >= self.session.n_ticks:
            raise ReplayFinished(f"{self.path}: end of recording")
        i = self._index
        self._index += 1
        state, error = self.session.state(i)
        if error is not None or state is None:
            raise DeviceFault(error or "recorded read failure")
        return state

    def recorded_late_periods(self) -> float:
        """How late the tick read last started in the recording: the daemon's watchdog
        repeats the recorded timing faults, so a replay's forces match the original's."""
        return float(self.session.late_periods[self._index - 1]) if self._index else 0.0

    def take_recorded_events(self) -> list[dict]:
        """Recorded control commands due at or before the tick read last, in order."""
        if self._index == 0:
            return []
        seq = self.session.seq[self._index - 1]
        events = self.session.events
        due = []
        while self._event_index < len(events) and events[self._event_index]["seq"] <= seq:
            due.append(events[self._event_index])
            self._event_index += 1
        return due

    def write_force(self, force_n: np.ndarray) -> None:
        self.last_force_n = np.asarray(force_n, dtype=np.float64).copy()


def open_replay(argument: str | None, speed: float | None = 1.0, **options) -> ReplayDevice:
    if not argument:
        raise DeviceOpenError("replay needs a file: --device replay:FILE")
    if not os.path.lexists(argument):
        raise DeviceOpenError(f"replay file {argument}: no such file")
    open_regular(
        argument, "recording", DeviceOpenError
    ).close()  # a FIFO or a device: one line, no hang
    return ReplayDevice(argument, speed=speed)


# what a replay repeats
REPLAYED_COMMANDS = ("set", "load", "reconnect", "view", "clutch", "recentre", "mark")


def apply_recorded_event(
    event: dict,
    pipeline: HapticPipeline,
    structure,
    settings: dict,
    limits: DeviceLimits,
    structure_for_sha,
) -> tuple[object, dict]:
    """Apply a recorded `set`/`load`/`reconnect`/`view`/`clutch`/`recentre` as the live daemon
    did; return (structure, settings).

    Live, the control thread builds new engines and the loop swaps them in; a replay
    (live or `--verify`) does the same steps in line, so the forces come out identical.
    """
    cmd, args = event.get("cmd"), event.get("args", {})
    if cmd == "set":
        haptic, _ = split_changes(args)
        if needs_rebuild(haptic):
            settings = validate_settings({**settings, **haptic}, limits)
            pipeline.replace_engine(build_engine(structure, limits, settings))
        elif haptic:
            pipeline.engine.update(**haptic)
            settings = validate_settings({**settings, **haptic}, limits)
    elif cmd == "load":
        structure = structure_for_sha(args["sha256"], args.get("keep_water", False))
        pipeline.replace_engine(build_engine(structure, limits, settings))
    elif cmd == "reconnect":
        pipeline.reconnected()
    elif cmd == "view":
        pipeline.set_view(validate_rotation(args["rotation"]))
    elif cmd == "clutch":
        pipeline.set_clutch(bool(args["held"]))
    elif cmd == "recentre":
        pipeline.recentre()
    return structure, settings
