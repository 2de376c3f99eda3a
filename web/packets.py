"""What the page is sent: binary packets of typed arrays with a JSON header, built from a
structure and a session (the live bridge sends them over the WebSocket, the HTML export
embeds them).

A packet is `SPK1`, a little-endian uint32 header length, the UTF-8 JSON header (padded
with spaces so the arrays start on 8 bytes), then the arrays, each starting on 8 bytes. The
header's `arrays` lists each one's `name`, `dtype` (`f8`, `f4`, `i4`, `u4`, `u2`, `u1`), `offset`
from the end of the header and `count` of elements; every other key is the packet's own
(`kind`, ...). The page reads them in page/packets.js.

Before any packet a page is sent `hello()`: protocol/view.py's conventions and the colours and
Phong terms of molecule/colors.py, so the page holds no copy of them.

Packets:
- `structure`: `name`, `sha256`, `n_atoms`; `positions` (f4, 3 a atom, Å), `radii` (f4,
  van der Waals, Å), `trace` (i4: consecutive trace atoms of one segment, a pair per line
  segment), `trace_colors` (u1, rgb a pair, the chain's colour). The atoms' colours travel
  apart, as a `colors` packet, since the scheme can change while the structure stays.
- `colors`: `scheme`, `sha256` (the structure's); `colors` (u1, rgb an atom).
- `poses` (the HTML export): `t_s`, seconds from the first pose, and the pose's fields a
  screen needs, one row a drawn frame (web/export.py).
"""

from __future__ import annotations

import json
import struct

import numpy as np
from sasprobe.molecule import Structure
from sasprobe.molecule.colors import (
    BACKGROUND,
    CUBE_WIRE_COLOR,
    FORCE_COLORS,
    HIGHLIGHT,
    LIT,
    MARK_COLOR,
    PROBE_COLOR,
    chain_colors,
    default_scheme,
    scheme_colors,
)
from sasprobe.protocol.view import conventions

MAGIC = b"SPK1"
ALIGN = 8
DTYPES = {
    "f8": np.float64,
    "f4": np.float32,
    "i4": np.int32,
    "u4": np.uint32,
    "u2": np.uint16,
    "u1": np.uint8,
}


def hello() -> dict:
    """What every page needs before it draws: protocol/view.py's conventions and the colours
    and Phong terms of molecule/colors.py (the page holds no copy of them)."""
    lit = LIT
    return {
        "type": "hello",
        "view": conventions(),
        "colors": {
            "background": BACKGROUND,
            "highlight": HIGHLIGHT,
            "probe": PROBE_COLOR,
            "cube_wire": CUBE_WIRE_COLOR,
            "mark": MARK_COLOR,
            "force": FORCE_COLORS,
        },
        "lit": {
            "ambient": lit.ambient,
            "directional": lit.directional,
            "probe": lit.probe,
            "probe_attenuation": lit.probe_attenuation,
            "probe_range": lit.probe_range,
            "shininess": lit.shininess,
            "specular": lit.specular,
        },
    }


def packet(header: dict, arrays: dict[str, np.ndarray]) -> bytes:
    """The packet of a header and named arrays (flattened, in the listed dtypes)."""
    listed, blobs, offset = [], [], 0
    for name, array in arrays.items():
        array = np.ascontiguousarray(array)
        code = next((k for k, v in DTYPES.items() if array.dtype == v), None)
        if code is None:
            raise ValueError(f"{name}: dtype {array.dtype} is not one a packet carries")
        listed.append({"name": name, "dtype": code, "offset": offset, "count": int(array.size)})
        blobs.append(array.astype(array.dtype.newbyteorder("<"), copy=False).tobytes())
        offset = _aligned(offset + len(blobs[-1]))
    text = json.dumps({**header, "arrays": listed}, separators=(",", ":")).encode()
    text = text.ljust(_aligned(len(MAGIC) + 4 + len(text)) - len(MAGIC) - 4)
    out = bytearray(MAGIC + struct.pack("<I", len(text)) + text)
    start = len(out)
    for entry, blob in zip(listed, blobs):
        out.extend(b"\0" * (start + entry["offset"] - len(out)))
        out.extend(blob)
    return bytes(out)


def read_packet(data: bytes) -> tuple[dict, dict[str, np.ndarray]]:
    """The header and arrays of a packet (what page/packets.js reads, for tests and tools)."""
    if data[:4] != MAGIC:
        raise ValueError("not a packet")
    (length,) = struct.unpack_from("<I", data, 4)
    header = json.loads(data[8 : 8 + length])
    start = 8 + length
    arrays = {
        a["name"]: np.frombuffer(data, DTYPES[a["dtype"]], a["count"], start + a["offset"])
        for a in header.pop("arrays")
    }
    return header, arrays


def _aligned(n: int) -> int:
    return -(-n // ALIGN) * ALIGN


def trace_pairs(structure: Structure) -> np.ndarray:
    """(K, 2) int32: the trace's line segments as pairs of consecutive atoms of one segment."""
    pairs = [np.column_stack((s[:-1], s[1:])) for s in structure.backbone if len(s) >= 2]
    if not pairs:
        return np.zeros((0, 2), dtype=np.int32)
    return np.concatenate(pairs).astype(np.int32)


def structure_packet(structure: Structure) -> bytes:
    """The atoms and the backbone trace (each line segment in its chain's colour)."""
    pairs = trace_pairs(structure)
    chain = chain_colors(structure)[pairs[:, 0]] if pairs.size else np.zeros((0, 3))
    return packet(
        {
            "kind": "structure",
            "name": structure.name,
            "sha256": structure.sha256,
            "n_atoms": int(structure.n_atoms),
        },
        {
            "positions": structure.positions.astype(np.float32),
            "radii": structure.vdw_radii.astype(np.float32),
            "trace": pairs,
            "trace_colors": _bytes(chain),
        },
    )


_DEFAULT_SCHEMES: dict[str, str] = {}  # sha256 -> the structure's default scheme


def effective_scheme(structure: Structure, scene: dict | None) -> str:
    """The scene's colour scheme, else the structure's default (molecule/colors.py; worked out
    once per structure: a scene changes with every turn of the view)."""
    scheme = (scene or {}).get("color_scheme")
    if scheme:
        return scheme
    if structure.sha256 not in _DEFAULT_SCHEMES:
        _DEFAULT_SCHEMES[structure.sha256] = default_scheme(structure)
    return _DEFAULT_SCHEMES[structure.sha256]


def colors_packet(structure: Structure, scheme: str, probe_radius: float | None = None) -> bytes:
    """The atoms' colours in a scheme; `sas` measures each atom's exposed area at the probe
    radius first (molecule/sas.py), which takes a while on a large structure."""
    areas = None
    if scheme == "sas":
        from sasprobe.molecule import DEFAULT_PROBE_RADIUS, UniformGrid
        from sasprobe.molecule.sas import shrake_rupley

        radius = DEFAULT_PROBE_RADIUS if probe_radius is None else probe_radius
        areas = shrake_rupley(
            UniformGrid(structure.positions, structure.expanded_radii(radius))
        ).areas
    colors = scheme_colors(structure, scheme, areas)
    return packet(
        {"kind": "colors", "scheme": scheme, "sha256": structure.sha256},
        {"colors": _bytes(colors)},
    )


def _bytes(colors: np.ndarray) -> np.ndarray:
    """rgb 0..1 as uint8 0..255."""
    return np.clip(np.rint(np.asarray(colors, dtype=np.float64) * 255.0), 0, 255).astype(np.uint8)
