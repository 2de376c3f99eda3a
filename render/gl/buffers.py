"""GPU buffers of one structure, uploaded once: the spheres, the index list of the
atoms drawn as spheres (rewritten in place when culling changes), the backbone trace
and the probe. The lighting passes may bind `spheres` (vec4 centre+radius, vec4 colour
per atom) as a storage buffer too.
"""

from __future__ import annotations

import numpy as np
from sasprobe.molecule import Structure

SPHERE_FORMAT = "4f 4f"  # centre xyz + radius, colour rgb + unused
BACKBONE_FORMAT = "3f 3f 1i"  # position, chain colour, trace atom id


def upload(buffer, data: np.ndarray) -> None:
    """`data` into `buffer`, grown (orphaned) first when it is too small; an empty array
    leaves 16 zero bytes, so the buffer can still be bound."""
    raw = data.tobytes() or b"\0" * 16
    if buffer.size < len(raw):
        buffer.orphan(len(raw))
    buffer.write(raw)


def sphere_records(structure: Structure) -> np.ndarray:
    """(N, 8) float32: centre, vdW radius, CPK colour, 1."""
    n = structure.n_atoms
    rec = np.ones((n, 8), dtype=np.float32)
    rec[:, :3] = structure.positions
    rec[:, 3] = structure.vdw_radii
    rec[:, 4:7] = structure.colors
    return rec


def backbone_vertices(structure: Structure, chain_colors: np.ndarray) -> np.ndarray:
    """Line-list vertices of the trace (two per segment), in BACKBONE_FORMAT as a record array;
    each segment in its chain's colour (`chain_colors`: per atom, molecule/colors.py)."""
    starts, ends = [], []
    for seg in structure.backbone:
        if len(seg) < 2:
            continue
        starts.append(seg[:-1])
        ends.append(seg[1:])
    dtype = np.dtype([("position", "<f4", 3), ("color", "<f4", 3), ("atom", "<i4")])
    if not starts:
        return np.zeros(0, dtype=dtype)
    a, b = np.concatenate(starts), np.concatenate(ends)
    col = np.asarray(chain_colors, dtype=np.float32)[a]
    out = np.zeros(2 * a.size, dtype=dtype)
    out["position"][0::2] = structure.positions[a]
    out["position"][1::2] = structure.positions[b]
    out["color"][0::2] = col
    out["color"][1::2] = col
    out["atom"][0::2] = a
    out["atom"][1::2] = b
    return out


class MoleculeBuffers:
    def __init__(self, ctx, structure: Structure, chain_colors: np.ndarray):
        self.ctx = ctx
        self.n_atoms = structure.n_atoms
        self.records = sphere_records(structure)
        self.spheres = ctx.buffer(self.records.tobytes())
        self.selection = ctx.buffer(reserve=max(self.n_atoms, 1) * 4)
        self.n_selected = 0
        self._last_selection: np.ndarray | None = None
        trace = backbone_vertices(structure, chain_colors)
        self.backbone = ctx.buffer(trace.tobytes() if trace.size else b"\x00" * 28)
        self.n_backbone_vertices = int(trace.size)
        self.probe = ctx.buffer(reserve=32)
        self.color_version = 0  # +1 whenever set_colors rewrites the atoms' colours

    @property
    def colors(self) -> np.ndarray:
        """The atoms' colours as drawn, (N, 3) float32."""
        return self.records[:, 4:7]

    def set_colors(self, colors: np.ndarray) -> None:
        """New per-atom colours (a colour scheme), written into the sphere buffer."""
        self.records[:, 4:7] = colors
        self.spheres.write(self.records.tobytes())
        self.color_version += 1

    def set_selection(self, ids: np.ndarray) -> None:
        """Write the ids of the atoms drawn as spheres (skipped when unchanged)."""
        if ids is self._last_selection:
            return
        if len(ids):
            self.selection.write(np.ascontiguousarray(ids, dtype=np.uint32).tobytes())
        self.n_selected = len(ids)
        self._last_selection = ids

    def set_probe(self, center: np.ndarray, radius: float, color) -> None:
        self.probe.write(np.array([*center, radius, *color, 1.0], dtype=np.float32).tobytes())

    def release(self) -> None:
        for b in (self.spheres, self.selection, self.backbone, self.probe):
            b.release()
