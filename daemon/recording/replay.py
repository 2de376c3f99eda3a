"""`--device replay:FILE`: a recorded session's device states, played back as a device.

Each read() returns the next recorded device state (or raises DeviceFault where the
recording has a failed read), so the daemon recomputes forces through the same
pipeline; it also hands the daemon the recorded control commands and how late each
tick was, so settings changes and timing faults recur where they happened. The daemon
paces the replay at the recorded rate times --speed (`max`: as fast as it can); after
the last state read() raises ReplayFinished (an EOFError).

The recording is read as a stream (`ReplaySession.stream()`: the control records and
blocks of ticks after `start`, in file order), so a replay of any length holds a few
blocks of ticks. A reader thread keeps PREFETCH_BLOCKS blocks ahead of the loop, so the
loop waits on the disk only where the reader falls that far behind (a replay at
`--speed max` from a slow disk).

The replay device reads the daemon's own recordings, so it lives here rather than in
devices/; the daemon registers its scheme (replay_scheme.py) with the device registry.
`apply_recorded_event` is how both a replaying daemon and `replay --verify` repeat a
recorded control command.
"""

from __future__ import annotations

import collections
import logging
import os
import queue
import threading
from collections.abc import Iterator
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
from sasprobe.protocol.recording import Recording, RecordingError
from sasprobe.protocol.ticks import CALIBRATED, HAS_STATE, TickBlock

from sasprobe.common.files import open_regular

log = logging.getLogger("sasprobe")

PREFETCH_BLOCKS = 4  # blocks of ticks the reader thread keeps ahead of a replaying loop


class ReplayFinished(EOFError):
    """The recording has no more device states."""


@dataclass
class ReplaySession:
    """A recording's replay: the `start` record it begins from and the structures attached so
    far, and its control records and ticks after `start` as a stream."""

    recording: Recording
    start: dict  # the `start` control record's args: settings, structure, device, rate
    structures: dict = field(default_factory=dict)  # sha256 -> (name, bytes), as they are met

    @property
    def path(self) -> Path:
        return self.recording.path

    @property
    def finished(self) -> bool:
        """The recorder closed the file (False: cut short by a crash)."""
        return self.recording.finished

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
        try:
            lim = dict(self.start["device"]["limits"])
            lim["workspace_min_mm"] = tuple(lim["workspace_min_mm"])
            lim["workspace_max_mm"] = tuple(lim["workspace_max_mm"])
            return DeviceLimits(**lim)
        except (KeyError, TypeError, ValueError) as exc:
            raise DeviceOpenError(
                f"{self.path}: the start record's device limits are damaged "
                f"({type(exc).__name__}: {exc})"
            ) from None

    def stream(self) -> Iterator[dict | TickBlock]:
        """The control records after `start` (dicts) and the ticks after it (blocks), in file
        order; each structure attached on the way joins `structures` before what follows it.
        A damaged part ends it with a RecordingError."""
        started = False
        for item in self.recording.stream():
            if isinstance(item, TickBlock):
                if started:
                    yield item
            elif item.topic == "attachment":
                self.structures.setdefault(item.data["sha256"], (item.data["name"], item.raw))
            elif item.topic == "control":
                if started:
                    yield item.data
                elif item.data.get("cmd") == "start":
                    started = True


def open_session(path: str | Path) -> ReplaySession:
    """A recording (finished or cut) opened for replay: its `start` record, its structure and
    a first tick checked; DeviceOpenError when it has none of them or is not a recording."""
    path = Path(path)
    start = None
    structures: dict = {}
    try:
        recording = Recording(path)
        stream = recording.stream()
        try:
            for item in stream:
                if isinstance(item, TickBlock):
                    if start is not None:
                        break
                elif item.topic == "attachment":
                    structures.setdefault(item.data["sha256"], (item.data["name"], item.raw))
                elif item.topic == "control" and start is None:
                    if item.data.get("cmd") == "start":
                        start = item.data["args"]
            else:
                if start is None:
                    raise DeviceOpenError(f"{path}: not a sasprobe recording (no start record)")
                raise DeviceOpenError(f"{path}: no recorded ticks")
        finally:
            stream.close()
    except RecordingError as exc:
        raise DeviceOpenError(str(exc)) from None
    if start.get("structure_sha256") not in structures:
        raise DeviceOpenError(f"{path}: the recorded structure is not attached")
    return ReplaySession(recording, start, structures)


def tick_state(block: TickBlock, row: int) -> tuple[DeviceState | None, str | None]:
    """A recorded tick's device state (None when the read gave none) and its read error."""
    state = None
    device = block.device[row]
    flags = int(device["device_flags"])
    if flags & HAS_STATE:
        state = DeviceState(
            t_ns=int(device["t_ns"]),
            position_mm=np.array(device["position_mm"]),
            orientation=np.array(device["orientation"]),
            velocity_mm_s=np.array(device["velocity_mm_s"]),
            buttons=int(device["buttons"]),
            calibrated=bool(flags & CALIBRATED),
        )
    return state, block.errors.get(row)


_END = object()


class _Prefetch:
    """A thread that reads a session's stream ahead into a bounded queue."""

    def __init__(self, session: ReplaySession) -> None:
        self._session = session
        self._queue: queue.Queue = queue.Queue(maxsize=PREFETCH_BLOCKS)
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="sasprobe-replay", daemon=True)
        self._thread.start()

    def _run(self) -> None:
        try:
            for entry in self._session.stream():
                if not self._put(entry):
                    return
            self._put(_END)
        except Exception as exc:  # a damaged part of the file: the replay ends there
            self._put(exc)

    def _put(self, entry) -> bool:
        while not self._stop.is_set():
            try:
                self._queue.put(entry, timeout=0.1)
                return True
            except queue.Full:
                continue
        return False

    def get(self):
        return self._queue.get()

    def close(self) -> None:
        self._stop.set()
        self._thread.join()


class ReplayDevice(HapticDevice):
    def __init__(self, path: str, speed: float | None = 1.0) -> None:
        self.path = Path(path)
        self.speed = speed
        self.session = open_session(self.path)
        self.last_force_n = np.zeros(3)
        self._prefetch: _Prefetch | None = None
        self._block: TickBlock | None = None
        self._row = 0
        self._seq = -1  # the tick read last
        self._late = 0.0
        self._events: collections.deque = collections.deque()
        recorded = self.session.start["device"]
        self._info = DeviceInfo(
            kind="replay",
            model=f"replay of {recorded.get('model', 'a device')}",
            limits=self.session.device_limits(),
            details={
                "file": self.path.name,
                "recorded_kind": recorded.get("kind"),
                "speed": "max" if speed is None else speed,
            },
        )

    @property
    def info(self) -> DeviceInfo:
        return self._info

    def open(self) -> None:
        self._stop_reading()
        self._block, self._row, self._seq, self._late = None, 0, -1, 0.0
        self._events.clear()
        self._prefetch = _Prefetch(self.session)

    def close(self) -> None:
        self.last_force_n = np.zeros(3)
        self._stop_reading()

    def _stop_reading(self) -> None:
        if self._prefetch is not None:
            self._prefetch.close()
            self._prefetch = None

    def reconnect(self) -> None:
        """A file does not go away: the recorded reconnects come back as recorded events,
        so the daemon's own attempts (after a recorded read failure) add nothing."""
        raise DeviceFault("a replay repeats the recorded reconnects")

    def recorded_session(self) -> ReplaySession:
        return self.session

    def _next_block(self) -> TickBlock:
        """The next block of ticks; the control records before it go to the event queue."""
        if self._prefetch is None:
            raise ReplayFinished(f"{self.path}: the replay is not open")
        while True:
            entry = self._prefetch.get()
            if isinstance(entry, TickBlock):
                return entry
            if isinstance(entry, dict):
                self._events.append(entry)
                continue
            self._stop_reading()
            if isinstance(entry, Exception):
                log.error("replay of %s ends early: %s", self.path, entry)
            raise ReplayFinished(f"{self.path}: end of recording")

    def read(self) -> DeviceState:
        while self._block is None or self._row >= len(self._block):
            self._block, self._row = self._next_block(), 0
        block, row = self._block, self._row
        self._row += 1
        self._seq = int(block.pose["seq"][row])
        self._late = float(block.device["late_periods"][row])
        state, error = tick_state(block, row)
        if error is not None or state is None:
            raise DeviceFault(error or "recorded read failure")
        return state

    def recorded_late_periods(self) -> float:
        """How late the tick read last started in the recording: the daemon's watchdog
        repeats the recorded timing faults, so a replay's forces match the original's."""
        return self._late

    def take_recorded_events(self) -> list[dict]:
        """Recorded control commands due at or before the tick read last, in order."""
        due = []
        events = self._events
        while events and events[0]["seq"] <= self._seq:
            due.append(events.popleft())
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
