"""A recording's ticks: the `ticks` channel's binary messages, and blocks of ticks as columns.

One `ticks` message holds consecutive ticks: a header, one fixed-size little-endian
record per tick (the device's input, then the published pose's 200 bytes) and the error
texts of the ticks whose read failed. The layout is protocol/schemas/ticks.json's
(protocol/README.md shows it); the struct formats and numpy dtypes here are built from
it. `TicksPacker` writes messages (the daemon's recorder); `decode_ticks` reads one into
a `TickBlock`, whose columns are numpy views of the message's bytes. Files of the first
format (one JSON `device` and one JSON `pose` message per tick) become the same blocks
through `JsonTicks`.
"""

from __future__ import annotations

import functools
import struct

import numpy as np
from sasprobe.protocol.pose import POSE_SIZE, POSE_VERSION, Pose
from sasprobe.protocol.schemas import pose_layout, ticks_layout

_NUMPY = {
    "uint16": "<u2",
    "uint32": "<u4",
    "uint64": "<u8",
    "int32": "<i4",
    "int64": "<i8",
    "float64": "<f8",
}
_STRUCT = {"uint16": "H", "uint32": "I", "uint64": "Q", "int32": "i", "int64": "q", "float64": "d"}

TICKS_VERSION = ticks_layout()["version"]
HEADER = struct.Struct(
    "<" + "".join(_STRUCT[f["type"]] for f in ticks_layout()["header"]["fields"])
)
RECORD_SIZE = ticks_layout()["record"]["size"]
_DEVICE_FIELDS = [f for f in ticks_layout()["record"]["fields"] if f["type"] != "pose"]
POSE_OFFSET = next(f["offset"] for f in ticks_layout()["record"]["fields"] if f["type"] == "pose")
# t_ns, position[3], orientation[4], velocity[3], late_periods, read_ns, buttons, flags, reserved
_DEVICE = struct.Struct(
    "<"
    + "".join(
        ("" if f["count"] == 1 else str(f["count"])) + _STRUCT[f["type"]] for f in _DEVICE_FIELDS
    )
)
if HEADER.size != ticks_layout()["header"]["size"] or _DEVICE.size != POSE_OFFSET:
    raise ImportError("protocol/schemas/ticks.json: its fields do not make the sizes it states")
if POSE_OFFSET + POSE_SIZE != RECORD_SIZE:
    raise ImportError("protocol/schemas/ticks.json: the record is not the device part and a pose")

# The pose's fields in a block: pose.json's record names (not the version, not the reserved word).
POSE_RECORD_FIELDS = tuple(f["record"] for f in pose_layout()["fields"] if f["record"] is not None)
_BITS = {f["name"]: 1 << f["bit"] for f in ticks_layout()["device_flags"]}
HAS_STATE, CALIBRATED, HAS_ERROR = _BITS["state"], _BITS["calibrated"], _BITS["error"]
_LENGTH = struct.Struct("<H")
MAX_ERROR_BYTES = 0xFFFF


class TicksDecodeError(ValueError):
    """A `ticks` message this reader cannot read."""


def _dtype(fields: list[tuple[str, str, int, int]], record_size: int) -> np.dtype:
    return np.dtype(
        {
            "names": [name for name, _, _, _ in fields],
            "formats": [_NUMPY[t] if n == 1 else (_NUMPY[t], (n,)) for _, t, n, _ in fields],
            "offsets": [offset for _, _, _, offset in fields],
            "itemsize": record_size,
        }
    )


def record_dtypes(record_size: int = RECORD_SIZE) -> tuple[np.dtype, np.dtype]:
    """(device, pose) views of a tick record: the device fields by their ticks.json names, the
    pose fields by their record names (pose.json), each at its offset in the record."""
    device = [
        (f["name"], f["type"], f["count"], f["offset"])
        for f in _DEVICE_FIELDS
        if not f.get("reserved")
    ]
    pose = [
        (f["record"], f["type"], f["count"], POSE_OFFSET + f["offset"])
        for f in pose_layout()["fields"]
        if f["record"] is not None
    ]
    return _dtype(device, record_size), _dtype(pose, record_size)


class TickBlock:
    """Consecutive recorded ticks as columns: `device[name]` (ticks.json's device fields) and
    `pose[name]` (the published pose, by pose.json's record names), both views of the
    records, and the error text of each tick whose read failed (row -> text)."""

    __slots__ = ("records", "device", "pose", "errors")

    def __init__(self, records: np.ndarray, errors: dict[int, str]) -> None:
        self.records = records  # (N,) items of the record size
        device_dtype, pose_dtype = _dtypes(records.dtype.itemsize)
        self.device = records.view(device_dtype)
        self.pose = records.view(pose_dtype)
        self.errors = errors

    def __len__(self) -> int:
        return int(self.records.shape[0])

    @property
    def seq(self) -> np.ndarray:
        return self.pose["seq"].astype(np.int64)

    @property
    def log_ns(self) -> np.ndarray:
        """When each tick was published (the daemon's monotonic clock): its log time."""
        return self.pose["publish_t_ns"]

    @property
    def has_state(self) -> np.ndarray:
        return (self.device["device_flags"] & HAS_STATE) != 0

    @property
    def calibrated(self) -> np.ndarray:
        return (self.device["device_flags"] & CALIBRATED) != 0

    def pose_at(self, row: int) -> Pose:
        p = self.pose[row]
        return Pose(
            seq=int(p["seq"]),
            device_t_ns=int(p["device_t_ns"]),
            publish_t_ns=int(p["publish_t_ns"]),
            proxy_A=np.array(p["proxy_A"]),
            goal_A=np.array(p["goal_A"]),
            force_N=np.array(p["force_N"]),
            tip_mm=np.array(p["tip_mm"]),
            orientation=np.array(p["orientation"]),
            buttons=int(p["buttons"]),
            touched_atom=int(p["touched_atom"]),
            flags=int(p["flags"]),
            cube_center_A=np.array(p["cube_center_A"]),
            cube_half_A=float(p["cube_half_A"]),
        )

    def rows(self, start: int, stop: int) -> TickBlock:
        errors = {i - start: e for i, e in self.errors.items() if start <= i < stop}
        return TickBlock(self.records[start:stop], errors)

    @staticmethod
    def join(blocks: list[TickBlock]) -> TickBlock:
        """One block of several, in order (records longer than this version's are cut to it
        where the blocks' record sizes differ)."""
        if len(blocks) == 1:
            return blocks[0]
        sizes = {b.records.dtype.itemsize for b in blocks}
        parts = [b.records for b in blocks]
        if len(sizes) > 1:
            parts = [_cut(p) for p in parts]
        errors: dict[int, str] = {}
        row = 0
        for b in blocks:
            errors.update({row + i: e for i, e in b.errors.items()})
            row += len(b)
        return TickBlock(np.concatenate(parts), errors)


def _cut(records: np.ndarray) -> np.ndarray:
    """Records as this version's: their first RECORD_SIZE bytes."""
    raw = records.view(np.uint8).reshape(len(records), records.dtype.itemsize)
    return np.ascontiguousarray(raw[:, :RECORD_SIZE]).view(_VOID)[:, 0]


_VOID = np.dtype((np.void, RECORD_SIZE))


@functools.cache
def _dtypes(record_size: int) -> tuple[np.dtype, np.dtype]:
    return record_dtypes(record_size)


def decode_ticks(message: bytes) -> TickBlock:
    """A `ticks` message as a block (its columns view the message's bytes)."""
    if len(message) < HEADER.size:
        raise TicksDecodeError(f"ticks message of {len(message)} bytes is shorter than its header")
    version, record_size, count, errors_size, _ = HEADER.unpack_from(message, 0)
    if version < TICKS_VERSION or record_size < RECORD_SIZE:
        raise TicksDecodeError(f"ticks layout version {version} ({record_size}-byte records)")
    end = HEADER.size + count * record_size
    if end + errors_size != len(message):
        raise TicksDecodeError(
            f"ticks message of {len(message)} bytes; its header says {end + errors_size}"
        )
    records = np.frombuffer(
        message, dtype=np.dtype((np.void, record_size)), count=count, offset=HEADER.size
    )
    block = TickBlock(records, {})
    if errors_size:
        flagged = np.flatnonzero(block.device["device_flags"] & HAS_ERROR)
        offset = end
        for row in flagged.tolist():
            (n,) = _LENGTH.unpack_from(message, offset)
            text = bytes(message[offset + 2 : offset + 2 + n])
            if len(text) != n:
                raise TicksDecodeError("ticks message: an error text runs past its end")
            block.errors[row] = text.decode("utf-8", errors="replace")
            offset += 2 + n
        if offset != len(message):
            raise TicksDecodeError("ticks message: its error texts do not fill the error table")
    return block


def ticks_span(message: bytes) -> tuple[int, int, int, int, int]:
    """(count, first seq, last seq, first and last publish time) of a `ticks` message."""
    block = decode_ticks(message)
    if not len(block):
        return 0, 0, 0, 0, 0
    seq, log = block.pose["seq"], block.pose["publish_t_ns"]
    return len(block), int(seq[0]), int(seq[-1]), int(log[0]), int(log[-1])


class TicksPacker:
    """Builds `ticks` messages (the recorder's writer thread): a tick is kept as it came, and
    a message is packed a field at a time for all its ticks, not a tick at a time."""

    def __init__(self) -> None:
        self._ticks: list[tuple] = []
        self.first_log_ns = 0
        self.last_log_ns = 0
        self.first_seq = 0

    @property
    def count(self) -> int:
        return len(self._ticks)

    def add(
        self,
        log_ns: int,
        device: tuple | None,
        error: str | None,
        late_periods: float,
        read_ns: int,
        pose: Pose,
    ) -> None:
        """One tick. `device` is (t_ns, position, orientation, velocity, buttons, calibrated)
        of the state the read gave, None when it gave none."""
        if not self._ticks:
            self.first_log_ns, self.first_seq = log_ns, pose.seq
        self.last_log_ns = log_ns
        self._ticks.append((device, error, late_periods, read_ns, pose))

    def take(self) -> bytes:
        """The message of the ticks added since the last take (then empty)."""
        ticks, self._ticks = self._ticks, []
        block = TickBlock(np.zeros(len(ticks), dtype=_VOID), {})
        device, pose = block.device, block.pose
        states = [t[0] for t in ticks]
        device["t_ns"] = [s[0] if s else 0 for s in states]
        device["position_mm"] = [s[1] if s else _ZEROS[:3] for s in states]
        device["orientation"] = [s[2] if s else _ZEROS for s in states]
        device["velocity_mm_s"] = [s[3] if s else _ZEROS[:3] for s in states]
        device["buttons"] = [int(s[4]) & 0xFFFFFFFF if s else 0 for s in states]
        device["late_periods"] = [t[2] for t in ticks]
        device["read_ns"] = [t[3] for t in ticks]
        device["device_flags"] = [
            (HAS_STATE | (CALIBRATED if s[5] else 0) if s else 0)
            | (HAS_ERROR if t[1] is not None else 0)
            for s, t in zip(states, ticks)
        ]
        errors = bytearray()
        for t in ticks:
            if t[1] is not None:
                text = t[1].encode("utf-8")[:MAX_ERROR_BYTES]
                errors += _LENGTH.pack(len(text)) + text
        poses = [t[4] for t in ticks]
        for name in POSE_RECORD_FIELDS:
            if name not in _MASKED:
                pose[name] = [getattr(p, name) for p in poses]
        for name, mask in _MASKED.items():  # as the pose codec writes them
            pose[name] = [getattr(p, name) & mask for p in poses]
        raw = block.records.view(np.uint8).reshape(len(ticks), RECORD_SIZE)
        raw[:, POSE_OFFSET : POSE_OFFSET + 2] = _POSE_VERSION_BYTES
        return (
            HEADER.pack(TICKS_VERSION, RECORD_SIZE, len(ticks), len(errors), 0)
            + block.records.tobytes()
            + bytes(errors)
        )


_ZEROS = np.zeros(4)
_MASKED = {"flags": 0xFFFF, "buttons": 0xFFFFFFFF}
_POSE_VERSION_BYTES = np.frombuffer(struct.pack("<H", POSE_VERSION), dtype=np.uint8)


def _vector(values, n: int) -> list[float]:
    if values is None:
        return [np.nan] * n
    return [np.nan if v is None else float(v) for v in values]


class JsonTicks:
    """Ticks of the first recording format, each its `device` and `pose` JSON records, put
    into a block as they come (JSON's null numbers come back as NaN; a state without
    calibration is calibrated), so no record outlives its row."""

    def __init__(self, capacity: int) -> None:
        self._capacity = capacity
        self._start()

    def _start(self) -> None:
        self._block = TickBlock(np.zeros(self._capacity, dtype=_VOID), {})
        self.count = 0

    def add(self, d: dict, p: dict) -> None:
        block, row = self._block, self.count
        flags = (HAS_STATE if d.get("t_ns") is not None else 0) | (
            CALIBRATED if d.get("calibrated", True) is not False else 0
        )
        if d.get("error") is not None:
            flags |= HAS_ERROR
            block.errors[row] = d["error"]
        block.device[row] = (
            d.get("t_ns") or 0,
            _vector(d.get("position_mm"), 3),
            _vector(d.get("orientation"), 4),
            _vector(d.get("velocity_mm_s"), 3),
            d.get("late_periods", 0.0),
            d.get("read_ns", 0),
            d.get("buttons") or 0,
            flags,
        )
        block.pose[row] = tuple(
            _vector(v, len(v)) if isinstance(v, list) else v
            for v in (p[name] for name in POSE_RECORD_FIELDS)
        )
        self.count += 1

    @property
    def full(self) -> bool:
        return self.count >= self._capacity

    def take(self) -> TickBlock:
        """The ticks added since the last take, as a block (then empty)."""
        block = self._block.rows(0, self.count)
        self._start()
        return block
