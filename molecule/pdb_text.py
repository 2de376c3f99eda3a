"""What gemmi reads leniently in a PDB file and sasprobe refuses: a file cut short, and a
coordinate that is not a number (gemmi reads `abc.de` or a blank field as 0.0 Å).

Each check returns the problem in a few words, or None; loading.py names the file.
"""

from __future__ import annotations

import re

import numpy as np

COORD_RECORDS = (b"ATOM  ", b"HETATM")
# Columns 31-54 of a coordinate record: x, y and z, 8 characters each.
_COORDINATES = re.compile(rb"^(?:ATOM  |HETATM).{24}(.{24})", re.M)


def truncation(text: bytes) -> str | None:
    """A PDB file cut short (gemmi would silently read the first part): the last line is
    an incomplete coordinate record, or the file starts like a wwPDB entry (HEADER) but
    lacks the END record every such entry ends with."""
    tail = text[-4096:].rstrip(b"\r\n \t")
    last = tail.rsplit(b"\n", 1)[-1].rstrip(b"\r")
    # Columns 1-66 hold everything up to the B-factor; a shorter final line was cut.
    if (
        not text.endswith((b"\n", b"\r"))
        and last.startswith(COORD_RECORDS)
        and len(last.rstrip()) < 66
    ):
        return "truncated PDB file (last coordinate line is incomplete)"
    if text.lstrip().startswith(b"HEADER") and not re.search(rb"(^|\n)END\s*$", tail):
        return "truncated PDB file (wwPDB entry without its END record)"
    return None


def bad_coordinate(text: bytes) -> str | None:
    """The first coordinate field that is not a number, with its line, or None."""
    fields = _COORDINATES.findall(text)
    try:  # all at once: a structure of 100,000 atoms is checked in milliseconds
        np.frombuffer(b"".join(fields), dtype="S8").astype(np.float64)
        return None
    except ValueError:
        pass
    for match in _COORDINATES.finditer(text):
        for axis in range(3):
            field = match.group(1)[8 * axis : 8 * axis + 8]
            try:
                float(field)
            except ValueError:
                line = text.count(b"\n", 0, match.start()) + 1
                value = field.decode("latin-1").strip()
                what = f"'{value}' is not a number" if value else "is blank"
                return f"line {line}: the {'xyz'[axis]} coordinate {what}"
    return None
