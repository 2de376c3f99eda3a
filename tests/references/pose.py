"""A decoder of the pose message built from protocol/README.md's table alone (offsets, sizes,
types), not from sasprobe.protocol.pose, so the code and the document are checked against
each other."""

from __future__ import annotations

import functools
import re
import struct
from pathlib import Path

README = Path(__file__).resolve().parents[2] / "protocol" / "README.md"
_FORMATS = {"uint16": "H", "uint32": "I", "uint64": "Q", "int32": "i", "int64": "q", "float64": "d"}


@functools.cache
def readme_pose_table() -> tuple[tuple[int, int, str, str], ...]:
    """(offset, size, type, field) rows of the README's pose table."""
    text = README.read_text()
    section = text[text.index("## `pose`") :]
    section = section[: section.index("\n#", 5)]  # up to the next heading
    rows = []
    for line in section.splitlines():
        m = re.match(
            r"\|\s*(\d+)\s*\|\s*(\d+)\s*\|\s*([a-z0-9]+(?:\[\d\])?)\s*\|\s*(`?[\w ]+`?)\s*\|", line
        )
        if m:
            rows.append((int(m.group(1)), int(m.group(2)), m.group(3), m.group(4).strip("` ")))
    return tuple(rows)


@functools.cache
def _readers() -> tuple[tuple[str, int, struct.Struct, bool], ...]:
    readers = []
    for offset, size, typ, name in readme_pose_table():
        base, _, count = typ.partition("[")
        n = int(count[:-1]) if count else 1
        fmt = struct.Struct("<" + _FORMATS[base] * n)
        assert fmt.size == size, f"README row {name}: size {size} does not match {typ}"
        readers.append((name, offset, fmt, n > 1))
    return tuple(readers)


def reference_decode(payload: bytes) -> dict:
    out = {}
    for name, offset, fmt, is_vector in _readers():
        values = fmt.unpack_from(payload, offset)
        out[name] = values if is_vector else values[0]
    return out
