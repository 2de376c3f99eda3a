"""Session recording to MCAP (https://mcap.dev), on its own thread.

The loop hands each tick to `offer_tick()`, which only appends a tuple to a bounded
queue (a full queue drops the tick and counts it), so recording never makes a tick
wait. The writer thread packs the queued ticks into binary `ticks` messages, consecutive
ticks in one message (protocol/ticks.py; at most MAX_BATCH_TICKS each), writes the JSON
records between them in queue order, and finishes an MCAP chunk and flushes the file at
least every `flush_interval_s`, so a daemon killed with SIGKILL loses at most that much
and leaves a file whose complete records `protocol.recording.Recording` still reads.

Channels (protocol/README.md describes them):
  ticks    every tick: the raw device state (the replay input: state or read error,
           lateness) and the published pose, in binary, many ticks a message
  scene    every scene the daemon published (JSON)
  control  every state-changing control command, with the tick it took effect at (JSON)
Structure files are attachments (their exact bytes, once per structure), so a recording
replays alone.

Memory stays flat however long the session: the MCAP writer's index of chunks (one entry
per flush, for the file's summary) is kept in an unnamed temporary file beside the
recording until the summary is written.
"""

from __future__ import annotations

import collections
import hashlib
import json
import logging
import os
import struct
import tempfile
import threading
import time
from dataclasses import dataclass
from pathlib import Path

from sasprobe.daemon.realtime import helper_priority
from sasprobe.devices.base import DeviceState
from sasprobe.protocol.pose import Pose
from sasprobe.protocol.recording import (
    FORMAT_VERSION,
    PROFILE,
    SCHEMAS,
    TICKS_ENCODING,
    TICKS_SCHEMA_ENCODING,
    TICKS_TOPIC,
)
from sasprobe.protocol.schemas import ticks_schema
from sasprobe.protocol.ticks import TicksPacker

from sasprobe import __version__
from sasprobe.common.errors import UserError

log = logging.getLogger("sasprobe")

FLUSH_INTERVAL_S = 0.05  # half the 100 ms a SIGKILL may lose, leaving room for a busy machine
QUEUE_LIMIT = 20_000  # items (about 5 s of ticks at 4 kHz, 20 s at 1 kHz)
MAX_BATCH_TICKS = 1024  # ticks in one `ticks` message, at most
_WAKE_S = 0.01


def _media_type(data: bytes) -> str:
    return "application/gzip" if data[:2] == b"\x1f\x8b" else "chemical/x-pdb-or-mmcif"


def _device_fields(state: DeviceState | None) -> tuple | None:
    if state is None:
        return None
    return (
        state.t_ns,
        state.position_mm,
        state.orientation,
        state.velocity_mm_s,
        state.buttons,
        state.calibrated,
    )


class _SpilledChunkIndexes:
    """Where the MCAP writer keeps its chunk index (it appends one entry per chunk and reads
    them all back when it writes the summary): each entry serialised into an unnamed file."""

    def __init__(self, folder: Path) -> None:
        self._file = tempfile.TemporaryFile(dir=folder, prefix=".sasprobe-index-")
        self.count = 0

    def append(self, index) -> None:
        from mcap.data_stream import RecordBuilder

        builder = RecordBuilder()
        index.write(builder)
        self._file.write(builder.end())
        self.count += 1

    def __iter__(self):
        from mcap.data_stream import ReadDataStream
        from mcap.records import ChunkIndex

        self._file.flush()
        self._file.seek(0)
        stream = ReadDataStream(self._file)
        for _ in range(self.count):
            _opcode, length = struct.unpack("<BQ", stream.read(9))
            start = stream.count
            index = ChunkIndex.read(stream)
            stream.read(length - (stream.count - start))  # fields a newer mcap may add
            yield index

    def __len__(self) -> int:
        return self.count

    def close(self) -> None:
        self._file.close()


@dataclass
class RecorderStats:
    path: str
    messages: int
    dropped: int
    bytes: int
    flushes: int
    max_flush_gap_s: float

    def as_dict(self) -> dict:
        return dict(self.__dict__)


class Recorder:
    """Writes one MCAP file from a bounded queue on its own thread."""

    def __init__(
        self,
        path: str | Path,
        metadata: dict | None = None,
        flush_interval_s: float = FLUSH_INTERVAL_S,
        queue_limit: int = QUEUE_LIMIT,
    ) -> None:
        from mcap.writer import CompressionType, Writer

        self.path = Path(path)
        try:  # a new file, 0600 whatever the umask, never through a symlink
            fd = os.open(
                self.path,
                os.O_WRONLY | os.O_CREAT | os.O_EXCL | os.O_NOFOLLOW | os.O_CLOEXEC,
                0o600,
            )
        except FileExistsError:
            raise UserError(f"{self.path}: already exists; record to a new file") from None
        except OSError as exc:
            raise UserError(f"{self.path}: cannot create ({exc.strerror or exc})") from None
        self._file = os.fdopen(fd, "wb")
        self._writer = Writer(self._file, compression=CompressionType.ZSTD)
        self._chunk_indexes = _SpilledChunkIndexes(self.path.parent)
        self._writer._Writer__chunk_indices = self._chunk_indexes  # see _SpilledChunkIndexes
        self._writer.start(profile=PROFILE, library=f"sasprobe {__version__}")
        schema_id = self._writer.register_schema(
            name="sasprobe.Ticks",
            encoding=TICKS_SCHEMA_ENCODING,
            data=json.dumps(ticks_schema()).encode(),
        )
        self._channels = {
            TICKS_TOPIC: self._writer.register_channel(
                topic=TICKS_TOPIC, message_encoding=TICKS_ENCODING, schema_id=schema_id
            )
        }
        for name, schema in SCHEMAS.items():
            schema_id = self._writer.register_schema(
                name=schema["title"], encoding="jsonschema", data=json.dumps(schema).encode()
            )
            self._channels[name] = self._writer.register_channel(
                topic=name, message_encoding="json", schema_id=schema_id
            )
        fields = {**(metadata or {}), "format": FORMAT_VERSION}
        self._writer.add_metadata("sasprobe", {k: str(v) for k, v in fields.items()})
        self._writer.flush()
        self._packer = TicksPacker()
        self._attached: set[bytes] = set()  # the structures in the file, by their bytes' hash
        self._queue: collections.deque = collections.deque()
        self._queue_limit = queue_limit
        self._flush_interval = flush_interval_s
        self._stop = threading.Event()
        self.messages = 0
        self.dropped = 0
        self.flushes = 0
        self.max_flush_gap_s = 0.0
        self._error: str | None = None
        self._thread = threading.Thread(target=self._run, name="sasprobe-recorder", daemon=True)
        self._thread.start()

    # --- called by the loop (never blocks) ---
    def _offer(self, item: tuple) -> bool:
        if len(self._queue) >= self._queue_limit or self._error is not None:
            self.dropped += 1
            return False
        self._queue.append(item)
        return True

    def offer_tick(
        self,
        log_t_ns: int,
        seq: int,
        state: DeviceState | None,
        error: str | None,
        late_periods: float,
        read_ns: int,
        pose: Pose,
    ) -> bool:
        return self._offer(("tick", log_t_ns, seq, state, error, late_periods, read_ns, pose))

    def offer_json(self, channel: str, log_t_ns: int, obj: dict) -> bool:
        return self._offer(("json", log_t_ns, channel, obj))

    def offer_structure(self, log_t_ns: int, name: str, data: bytes) -> bool:
        return self._offer(("attachment", log_t_ns, name, data))

    # --- the writer thread ---
    def _write_ticks(self) -> None:
        """The ticks packed so far as one `ticks` message (log time: the first tick's)."""
        packer = self._packer
        if not packer.count:
            return
        first, last, seq = packer.first_log_ns, packer.last_log_ns, packer.first_seq
        self._writer.add_message(
            self._channels[TICKS_TOPIC], first, packer.take(), last, seq & 0xFFFFFFFF
        )
        self.messages += 1

    def _write(self, item: tuple) -> None:
        kind, t = item[0], item[1]
        if kind == "tick":
            _, _, _seq, state, error, late, read_ns, pose = item
            self._packer.add(t, _device_fields(state), error, late, read_ns, pose)
            if self._packer.count >= MAX_BATCH_TICKS:
                self._write_ticks()
            return
        self._write_ticks()  # the ticks before this record stay before it
        if kind == "json":
            _, _, channel, obj = item
            data = json.dumps(obj, allow_nan=False).encode()
            self._writer.add_message(self._channels[channel], t, data, t)
            self.messages += 1
        else:
            _, _, name, data = item
            digest = hashlib.sha256(data).digest()
            if digest in self._attached:
                return
            self._attached.add(digest)
            self._writer.add_attachment(
                create_time=0, log_time=t, name=name, media_type=_media_type(data), data=data
            )

    def _drain(self) -> None:
        queue = self._queue
        while queue:
            self._write(queue.popleft())
        self._write_ticks()

    def _run(self) -> None:
        helper_priority()
        last_flush = time.monotonic()
        try:
            while not self._stop.is_set():
                self._stop.wait(_WAKE_S)
                self._drain()
                now = time.monotonic()
                if now - last_flush >= self._flush_interval:
                    self._writer.flush()  # ends the chunk and hands it to the OS: survives SIGKILL
                    self.flushes += 1
                    self.max_flush_gap_s = max(self.max_flush_gap_s, now - last_flush)
                    last_flush = now
            self._drain()
        except Exception as exc:  # disk full, file gone: stop recording, keep the daemon running
            self._error = f"{type(exc).__name__}: {exc}"
            log.error("recording to %s failed: %s", self.path, self._error)

    def stats(self) -> RecorderStats:
        size = self.path.stat().st_size if self.path.exists() else 0
        return RecorderStats(
            str(self.path), self.messages, self.dropped, size, self.flushes, self.max_flush_gap_s
        )

    @property
    def error(self) -> str | None:
        return self._error

    def close(self) -> RecorderStats:
        """Drain the queue, write the summary (index) and close the file."""
        self._stop.set()
        self._thread.join()
        try:
            if self._error is None:
                self._writer.finish()
        finally:
            self._file.close()
            self._chunk_indexes.close()
        return self.stats()
