"""Recordings: the MCAP file a daemon writes (`--record`), its channels and their JSON,
and reading it back, including files whose writer was killed (no summary, cut record).

The format is documented in protocol/README.md. The daemon writes it
(daemon/recording/writer.py); the daemon's replay and `replay --verify`, and the
renderer's `replay --video`, read it through this module, so a renderer needs no daemon
code to draw a recorded session.

Reading: a finished MCAP file ends with a summary and footer; a file of a daemon killed
with SIGKILL ends after its last flushed chunk, possibly in the middle of a record. The
reader walks the top-level records, stops before the first incomplete one and reads
everything up to there in file order. `recover()` writes such a prefix out again as a
finished, indexed MCAP file.
"""

from __future__ import annotations

import hashlib
import io
import json
import math
import struct
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from sasprobe.protocol.pose import Pose
from sasprobe.protocol.schemas import channel_schemas, pose_layout

from sasprobe.common.errors import UserError
from sasprobe.common.files import open_regular

MAGIC = b"\x89MCAP0\r\n"
_OPCODE_FOOTER = 0x02
PROFILE = "sasprobe"

# Each channel's JSON Schema (protocol/schemas/), standalone, as the writer embeds it
# (encoding `jsonschema`).
SCHEMAS = channel_schemas()


def json_floats(values) -> list:
    """A vector as JSON numbers; non-finite entries become null (JSON has no NaN)."""
    floats = np.asarray(values, dtype=np.float64).tolist()
    if all(map(math.isfinite, floats)):
        return floats
    return [x if math.isfinite(x) else None for x in floats]


# The `pose` channel's fields: pose.json's record names (neither the version nor the reserved word).
POSE_RECORD_FIELDS = tuple(f["record"] for f in pose_layout()["fields"] if f["record"] is not None)
_POSE_VECTORS = frozenset(
    f["record"] for f in pose_layout()["fields"] if f["record"] is not None and f["count"] > 1
)


def pose_record(pose: Pose) -> dict:
    """A pose as the `pose` channel's JSON (non-finite numbers as null)."""
    record = {}
    for name in POSE_RECORD_FIELDS:
        value = getattr(pose, name)
        record[name] = (
            json_floats(value)
            if name in _POSE_VECTORS
            else float(value)
            if name == "cube_half_A"
            else int(value)
        )
    return record


def pose_from_record(record: dict) -> Pose:
    """The inverse of pose_record (null numbers come back as NaN)."""
    values = {}
    for name in POSE_RECORD_FIELDS:
        v = record[name]
        values[name] = (
            np.array([np.nan if x is None else x for x in v], dtype=np.float64)
            if name in _POSE_VECTORS
            else v
        )
    return Pose(**values)


class RecordingError(UserError):
    """A file that is not a readable sasprobe recording."""


@dataclass
class Scan:
    end: int  # bytes of complete records (plus the closing magic when finished)
    size: int
    finished: bool  # a footer was found: the writer closed the file


def scan(path: Path) -> Scan:
    """Find where the complete records end, reading only record headers."""
    path = Path(path)
    with open_regular(path, "recording", RecordingError) as fh:
        size = fh.seek(0, io.SEEK_END)
        fh.seek(0)
        if fh.read(len(MAGIC)) != MAGIC:
            raise RecordingError(f"{path}: not an MCAP file")
        offset = len(MAGIC)
        while offset + 9 <= size:
            fh.seek(offset)
            opcode, length = struct.unpack("<BQ", fh.read(9))
            end = offset + 9 + length
            if end > size:
                break
            if opcode == _OPCODE_FOOTER:
                if end + len(MAGIC) <= size:
                    return Scan(end=end + len(MAGIC), size=size, finished=True)
                break  # the closing magic was cut: read up to the footer
            offset = end
        return Scan(end=offset, size=size, finished=False)


class _Prefix(io.RawIOBase):
    """The first `end` bytes of a file, so the MCAP stream reader stops at a record boundary."""

    def __init__(self, fh, end: int) -> None:
        self._fh = fh
        self._left = end

    def readable(self) -> bool:
        return True

    def readinto(self, buffer) -> int:
        n = min(len(buffer), self._left)
        if n <= 0:
            return 0
        data = self._fh.read(n)
        buffer[: len(data)] = data
        self._left -= len(data)
        return len(data)


@dataclass
class Item:
    """One message (topic + decoded JSON) or attachment (topic 'attachment') in file order."""

    topic: str
    log_time: int
    data: dict = field(default_factory=dict)
    raw: bytes = b""  # attachment bytes, or the message's JSON bytes


def iter_items(path: Path, decode: bool = True) -> Iterator[Item]:
    """Messages and attachments of a recording, finished or not, in file order."""
    from mcap.exceptions import EndOfFile
    from mcap.records import Attachment, Channel, Message, Metadata
    from mcap.stream_reader import StreamReader

    path = Path(path)
    info = scan(path)
    channels: dict[int, str] = {}
    with open_regular(path, "recording", RecordingError) as fh:
        reader = StreamReader(io.BufferedReader(_Prefix(fh, info.end)), skip_magic=False)
        try:
            for record in reader.records:
                if isinstance(record, Channel):
                    channels[record.id] = record.topic
                elif isinstance(record, Message):
                    topic = channels.get(record.channel_id, f"channel-{record.channel_id}")
                    data = json.loads(record.data) if decode else {}
                    yield Item(topic, record.log_time, data, record.data)
                elif isinstance(record, Attachment):
                    yield Item(
                        "attachment",
                        record.log_time,
                        {
                            "name": record.name,
                            "media_type": record.media_type,
                            "sha256": hashlib.sha256(record.data).hexdigest(),
                        },
                        record.data,
                    )
                elif isinstance(record, Metadata):
                    yield Item("metadata", 0, {"name": record.name, **record.metadata})
        except EndOfFile:
            return  # an unfinished file: everything complete has been read
        except (
            Exception
        ) as exc:  # mcap's, zstd's, json's and struct's errors alike: the file is damaged
            raise RecordingError(
                f"{path}: damaged recording ({type(exc).__name__}: {_first_line(exc)})"
            ) from None


@dataclass
class Summary:
    path: str
    finished: bool
    bytes_total: int
    bytes_readable: int
    counts: dict  # messages per topic
    first_log_ns: int | None
    last_log_ns: int | None
    ticks: int
    seq_gaps: int  # ticks missing between the first and last recorded one (queue overflow)
    structures: list[str]
    metadata: dict

    @property
    def duration_s(self) -> float:
        if self.first_log_ns is None or self.last_log_ns is None:
            return 0.0
        return (self.last_log_ns - self.first_log_ns) / 1e9

    def as_dict(self) -> dict:
        return {**self.__dict__, "duration_s": self.duration_s}


def summarize(path: Path) -> Summary:
    info = scan(path)
    counts: dict[str, int] = {}
    first = last = None
    seqs_first = seqs_last = None
    ticks = 0
    structures: list[str] = []
    metadata: dict = {}
    for item in iter_items(path):
        if item.topic == "attachment":
            structures.append(item.data["name"])
            continue
        if item.topic == "metadata":
            metadata = {k: v for k, v in item.data.items() if k != "name"}
            continue
        counts[item.topic] = counts.get(item.topic, 0) + 1
        first = item.log_time if first is None else min(first, item.log_time)
        last = item.log_time if last is None else max(last, item.log_time)
        if item.topic == "device":
            seq = item.data["seq"]
            seqs_first = seq if seqs_first is None else seqs_first
            seqs_last = seq
            ticks += 1
    gaps = (seqs_last - seqs_first + 1 - ticks) if ticks else 0
    return Summary(
        str(path),
        info.finished,
        info.size,
        info.end,
        counts,
        first,
        last,
        ticks,
        gaps,
        structures,
        metadata,
    )


def recover(path: Path, out: Path) -> Summary:
    """Write the readable part of a (possibly unfinished) recording as a finished MCAP file."""
    path, out = Path(path), Path(out)
    if out.exists():
        raise RecordingError(f"{out}: already exists")
    info = scan(path)
    try:
        dst = open(out, "xb")
    except OSError as exc:
        raise RecordingError(f"{out}: cannot create ({exc.strerror or exc})") from None
    try:
        with open_regular(path, "recording", RecordingError) as src, dst:
            _copy_records(src, dst, info.end, path)
    except BaseException:
        out.unlink(missing_ok=True)  # no half-written copy is left behind
        raise
    return summarize(out)


def _copy_records(src, dst, end: int, path: Path) -> None:
    from mcap.exceptions import EndOfFile
    from mcap.records import Attachment, Channel, Message, Metadata, Schema
    from mcap.stream_reader import StreamReader
    from mcap.writer import CompressionType, Writer

    writer = Writer(dst, compression=CompressionType.ZSTD)
    writer.start(profile=PROFILE, library="sasprobe recover")
    schema_ids: dict[int, int] = {}
    channel_ids: dict[int, int] = {}
    try:
        for record in StreamReader(io.BufferedReader(_Prefix(src, end))).records:
            if isinstance(record, Schema):
                schema_ids[record.id] = writer.register_schema(
                    record.name, record.encoding, record.data
                )
            elif isinstance(record, Channel):
                channel_ids[record.id] = writer.register_channel(
                    record.topic,
                    record.message_encoding,
                    schema_ids.get(record.schema_id, 0),
                    record.metadata,
                )
            elif isinstance(record, Message):
                writer.add_message(
                    channel_ids[record.channel_id],
                    record.log_time,
                    record.data,
                    record.publish_time,
                    record.sequence,
                )
            elif isinstance(record, Attachment):
                writer.flush()
                writer.add_attachment(
                    record.create_time, record.log_time, record.name, record.media_type, record.data
                )
            elif isinstance(record, Metadata):
                writer.add_metadata(record.name, record.metadata)
    except EndOfFile:
        pass
    except Exception as exc:  # mcap's, zstd's and struct's errors alike: a damaged file
        raise RecordingError(
            f"{path}: damaged recording ({type(exc).__name__}: {_first_line(exc)})"
        ) from None
    writer.finish()


def _first_line(exc: BaseException) -> str:
    text = str(exc).strip()
    return text.splitlines()[0][:200] if text else ""
