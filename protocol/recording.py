"""Recordings: the MCAP file a daemon writes (`--record`), its channels, and reading it
back as a stream, including files whose writer was killed (no summary, cut record).

The format is documented in protocol/README.md. The daemon writes it
(daemon/recording/writer.py); the daemon's replay, `replay --verify` and `--findings`,
and the renderer's `replay --video` read it through this module (`Recording`), so a
renderer needs no daemon code to draw a recorded session. The ticks' binary layout and
its codec are protocol/ticks.py's. Files of the first format (a JSON `device` and `pose`
message per tick) are read as well, into the same blocks of ticks.

Reading: a finished MCAP file ends with a summary and footer; a file of a daemon killed
with SIGKILL ends after its last flushed chunk, possibly in the middle of a record. The
reader walks the top-level records, stops before the first incomplete one and reads
everything up to there in file order, one chunk at a time, so a reader's memory does not
grow with the file. `recover()` writes such a prefix out again as a finished, indexed
MCAP file.
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
from sasprobe.protocol.schemas import channel_schemas
from sasprobe.protocol.ticks import (
    JsonTicks,
    TickBlock,
    TicksDecodeError,
    decode_ticks,
    ticks_span,
)

from sasprobe.common.errors import UserError
from sasprobe.common.files import open_regular

MAGIC = b"\x89MCAP0\r\n"
_OPCODE_FOOTER = 0x02
PROFILE = "sasprobe"

# The JSON channels' schemas (protocol/schemas/), standalone, as the writer embeds them
# (schema encoding `jsonschema`).
SCHEMAS = channel_schemas()


def json_floats(values) -> list:
    """A vector as JSON numbers; non-finite entries become null (JSON has no NaN)."""
    floats = np.asarray(values, dtype=np.float64).tolist()
    if all(map(math.isfinite, floats)):
        return floats
    return [x if math.isfinite(x) else None for x in floats]


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
    """One message (topic + decoded JSON; a `ticks` message keeps its bytes only), attachment
    (topic 'attachment') or metadata record (topic 'metadata'), in file order."""

    topic: str
    log_time: int
    data: dict = field(default_factory=dict)
    raw: bytes = b""  # attachment bytes, or the message's bytes


TICKS_TOPIC = "ticks"
TICKS_ENCODING = "sasprobe.ticks"  # the `ticks` channel's message encoding (ticks.json's layout)
TICKS_SCHEMA_ENCODING = "sasprobe.layout"  # its schema: ticks.json with pose.json, as JSON
FORMAT_VERSION = 2  # the `sasprobe` metadata's `format`; files without it are format 1
BLOCK_TICKS = 4096  # ticks per block that Recording.stream() hands out, at most
COPY_CHUNK_BYTES = 1 << 20  # a recovered copy's chunks (what its writer holds before writing)


class Recording:
    """A recording opened for reading, finished or not. Where its complete records end is found
    once, when it is opened, so that every pass over it reads the same records even while a
    daemon is still writing the file.

    `items()` gives the records in file order; `stream()` gives the same with the ticks in
    blocks (protocol/ticks.py), whichever format wrote them. Either holds one chunk of the
    file and one block at a time: memory does not grow with the recording's length."""

    def __init__(self, path: str | Path) -> None:
        self.path = Path(path)
        info = scan(self.path)
        self.end, self.size, self.finished = info.end, info.size, info.finished

    def items(self, decode: bool = True) -> Iterator[Item]:
        """Messages, attachments and metadata up to the end found when opened, in file order."""
        from mcap.exceptions import EndOfFile
        from mcap.records import Attachment, Channel, Message, Metadata
        from mcap.stream_reader import StreamReader

        path = self.path
        channels: dict[int, tuple[str, bool]] = {}  # id -> (topic, JSON)
        with open_regular(path, "recording", RecordingError) as fh:
            reader = StreamReader(io.BufferedReader(_Prefix(fh, self.end)), skip_magic=False)
            try:
                for record in reader.records:
                    if isinstance(record, Message):
                        topic, is_json = channels.get(
                            record.channel_id, (f"channel-{record.channel_id}", False)
                        )
                        data = json.loads(record.data) if decode and is_json else {}
                        yield Item(topic, record.log_time, data, record.data)
                    elif isinstance(record, Channel):
                        channels[record.id] = (record.topic, record.message_encoding == "json")
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
            except RecordingError:
                raise
            except Exception as exc:  # mcap's, zstd's, json's and struct's errors alike
                raise _damaged(path, exc) from None

    def stream(self, block_ticks: int | None = None) -> Iterator[Item | TickBlock]:
        """The records in file order, with consecutive ticks joined into TickBlocks of at most
        block_ticks (a record between ticks ends a block, so the order is kept exactly).

        Format 1 ticks are a `device` and a `pose` message each, written one after the other;
        a tick counts once both are there (the last one of a cut file may lack its pose)."""
        block_ticks = block_ticks or BLOCK_TICKS
        pending: list[TickBlock] = []
        count = 0
        device: dict | None = None  # format 1: a device record waiting for its pose
        first_format = JsonTicks(block_ticks)
        try:
            for item in self.items():
                topic = item.topic
                if topic == TICKS_TOPIC:
                    block = decode_ticks(item.raw)
                    pending.append(block)
                    count += len(block)
                elif topic == "device":
                    device = item.data
                    continue
                elif topic == "pose":
                    if device is not None and device.get("seq") == item.data.get("seq"):
                        first_format.add(device, item.data)
                        device = None
                        if first_format.full:
                            yield first_format.take()
                    continue
                else:
                    if first_format.count:
                        pending.append(first_format.take())
                    if pending:
                        yield TickBlock.join(pending)
                        pending, count = [], 0
                    yield item
                    continue
                while count >= block_ticks:
                    whole = TickBlock.join(pending)
                    yield whole.rows(0, block_ticks)
                    rest = whole.rows(block_ticks, len(whole))
                    pending, count = ([rest], len(rest)) if len(rest) else ([], 0)
            if first_format.count:
                pending.append(first_format.take())
            if pending:
                yield TickBlock.join(pending)
        except (TicksDecodeError, KeyError, TypeError, ValueError) as exc:
            raise _damaged(self.path, exc) from None


def _damaged(path: Path, exc: BaseException) -> RecordingError:
    return RecordingError(f"{path}: damaged recording ({type(exc).__name__}: {_first_line(exc)})")


def iter_items(path: Path, decode: bool = True) -> Iterator[Item]:
    """Messages and attachments of a recording, finished or not, in file order."""
    return Recording(path).items(decode)


@dataclass
class Summary:
    path: str
    finished: bool
    bytes_total: int
    bytes_readable: int
    format: int  # 2: a `ticks` channel; 1: a JSON `device` and `pose` message per tick
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
    recording = Recording(path)
    counts: dict[str, int] = {}
    first = last = None
    seqs_first = seqs_last = None
    ticks = 0
    structures: list[str] = []
    metadata: dict = {}
    try:
        for item in recording.items(decode=False):
            topic = item.topic
            if topic == "attachment":
                structures.append(item.data["name"])
                continue
            if topic == "metadata":
                metadata = {k: v for k, v in item.data.items() if k != "name"}
                continue
            counts[topic] = counts.get(topic, 0) + 1
            lo = hi = item.log_time
            if topic == TICKS_TOPIC:
                n, seq_lo, seq_hi, lo, hi = ticks_span(item.raw)
                if not n:
                    continue
            elif topic == "device":
                n, seq_lo = 1, json.loads(item.raw)["seq"]
                seq_hi = seq_lo
            else:
                n = 0
            first = lo if first is None else min(first, lo)
            last = hi if last is None else max(last, hi)
            if n:
                seqs_first = seq_lo if seqs_first is None else seqs_first
                seqs_last = seq_hi
                ticks += n
    except (TicksDecodeError, KeyError, TypeError, ValueError) as exc:
        raise _damaged(recording.path, exc) from None
    gaps = (seqs_last - seqs_first + 1 - ticks) if ticks else 0
    return Summary(
        str(path),
        recording.finished,
        recording.size,
        recording.end,
        FORMAT_VERSION if TICKS_TOPIC in counts else 1,
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

    writer = Writer(dst, chunk_size=COPY_CHUNK_BYTES, compression=CompressionType.ZSTD)
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
