"""A decoder of the recording's `ticks` messages built from protocol/README.md's tables
alone (the header, the tick record and the device flags of "The `ticks` channel"), not
from sasprobe.protocol.ticks, so the code and the document are checked against each other.
The pose inside each record is decoded with tests/references/pose.py."""

from __future__ import annotations

import functools
import struct

from tests.references.pose import README, reference_decode

_FORMATS = {"uint16": "H", "uint32": "I", "uint64": "Q", "int32": "i", "int64": "q", "float64": "d"}


@functools.cache
def _section() -> str:
    text = README.read_text()
    section = text[text.index("### The `ticks` channel") :]
    return section[: section.index("\n#", 5)]


@functools.cache
def readme_ticks_tables() -> tuple[tuple, tuple, dict]:
    """(header rows, record rows, device flag bits by name): each row (offset, size, type,
    field) as the README lists it."""
    tables: list[list[str]] = []
    previous = ""
    for line in _section().splitlines():
        if line.startswith("|"):
            if not previous.startswith("|"):
                tables.append([])
            tables[-1].append(line)
        previous = line
    layouts, flags = [], {}
    for table in tables:
        cells = [[c.strip().strip("`") for c in row.strip("|").split("|")] for row in table[2:]]
        if table[0].startswith("| offset"):
            layouts.append(tuple((int(c[0]), int(c[1]), c[2], c[3]) for c in cells))
        elif table[0].startswith("| bit"):
            flags = {c[2]: 1 << int(c[0]) for c in cells}
    header, record = layouts
    return header, record, flags


def _read(rows, data: bytes, base: int) -> dict:
    out = {}
    for offset, size, typ, name in rows:
        kind, _, count = typ.partition("[")
        if kind == "pose":
            out[name] = reference_decode(data[base + offset : base + offset + size])
            continue
        n = int(count[:-1]) if count else 1
        fmt = struct.Struct("<" + _FORMATS[kind] * n)
        assert fmt.size == size, f"README row {name}: size {size} does not match {typ}"
        values = fmt.unpack_from(data, base + offset)
        out[name] = values if n > 1 else values[0]
    return out


def reference_decode_ticks(message: bytes) -> dict:
    """{"header": {...}, "ticks": [record dict with "pose" decoded and "error" (text or None)]}."""
    header_rows, record_rows, flags = readme_ticks_tables()
    header = _read(header_rows, message, 0)
    header_size = sum(size for _, size, _, _ in header_rows)
    ticks = []
    for k in range(header["count"]):
        tick = _read(record_rows, message, header_size + k * header["record_size"])
        tick["error"] = None
        ticks.append(tick)
    at = header_size + header["count"] * header["record_size"]
    assert len(message) == at + header["errors_size"], "message size"
    for tick in ticks:
        if tick["device_flags"] & flags["error"]:
            (n,) = struct.unpack_from("<H", message, at)
            tick["error"] = message[at + 2 : at + 2 + n].decode("utf-8")
            at += 2 + n
    assert at == len(message), "error texts"
    return {"header": header, "ticks": ticks}
