"""A test's look at a (small) recording: all of it in memory, two ways.

`read_session` reads it through sasprobe's replay reader (open_session and its stream),
the way the daemon and `replay --verify` do, into whole arrays. `reference_ticks` reads it
with the mcap library and the README-table decoder of tests/references/ticks.py, sharing
nothing with sasprobe's reader."""

from __future__ import annotations

import io
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from sasprobe.daemon.recording.replay import open_session, tick_state
from sasprobe.protocol.ticks import TickBlock

from tests.references.ticks import reference_decode_ticks


@dataclass
class RecordedSession:
    start: dict
    structures: dict  # sha256 -> (name, bytes)
    events: list  # control records after `start`
    ticks: TickBlock  # every tick after `start`
    finished: bool

    @property
    def n_ticks(self) -> int:
        return len(self.ticks)

    @property
    def seq(self) -> np.ndarray:
        return self.ticks.seq

    @property
    def missing_ticks(self) -> int:
        seq = self.seq
        return int(seq[-1] - seq[0] + 1 - seq.size) if seq.size else 0

    @property
    def force_n(self) -> np.ndarray:
        return self.ticks.pose["force_N"]

    @property
    def flags(self) -> np.ndarray:
        return self.ticks.pose["flags"].astype(np.int64)

    @property
    def errors(self) -> dict[int, str]:
        return self.ticks.errors

    @property
    def has_state(self) -> np.ndarray:
        return self.ticks.has_state

    @property
    def late_periods(self) -> np.ndarray:
        return self.ticks.device["late_periods"]

    @property
    def position_mm(self) -> np.ndarray:
        return self.ticks.device["position_mm"]

    @property
    def structure_bytes(self) -> bytes:
        return self.structures[self.start["structure_sha256"]][1]

    def state(self, i: int):
        return tick_state(self.ticks, i)


def read_session(path: str | Path) -> RecordedSession:
    session = open_session(path)
    events, blocks = [], []
    for entry in session.stream():
        (blocks if isinstance(entry, TickBlock) else events).append(entry)
    return RecordedSession(
        session.start, session.structures, events, TickBlock.join(blocks), session.finished
    )


def read_whole_track(path: str | Path):
    """The findings' track of a recording (daemon/findings/session.py) after one pass, with
    its blocks joined into whole arrays: `track.proxy_A`, `track.contact`, ..."""
    from types import SimpleNamespace

    from sasprobe.daemon.findings.session import read_track

    track = read_track(path)
    blocks = list(track.blocks())
    columns = ("seq", "t_s", "dt_s", "proxy_A", "force_N", "contact", "touched_atom")
    joined = {name: np.concatenate([getattr(b, name) for b in blocks]) for name in columns}
    return SimpleNamespace(**vars(track), **joined)


class _ForwardOnly(io.RawIOBase):
    """A file read front to back: the mcap library then reads record by record, and a file cut
    short (a crash, a full disk) reads up to its cut."""

    def __init__(self, f) -> None:
        self._f = f

    def readable(self) -> bool:
        return True

    def readinto(self, buffer) -> int:
        return self._f.readinto(buffer)


def reference_ticks(path: str | Path, cut: bool = False) -> list[dict]:
    """Every recorded tick, in file order, as the README's tables decode it: the device's
    fields, "error", and "pose" (its fields by their wire names). `cut`: the file may end
    without its summary, its last record perhaps incomplete."""
    from mcap.exceptions import McapError
    from mcap.reader import make_reader

    ticks = []
    with open(path, "rb") as f:
        reader = make_reader(io.BufferedReader(_ForwardOnly(f)) if cut else f)
        try:
            for _, channel, message in reader.iter_messages(topics=["ticks"], log_time_order=False):
                assert channel.message_encoding == "sasprobe.ticks"
                ticks += reference_decode_ticks(message.data)["ticks"]
        except (McapError, EOFError):
            if not cut:
                raise
    return ticks
