"""The lights' shadow rays without the grid walk: light buffers (Haines & Greenberg, "The
Light Buffer: A Shadow-Testing Accelerator", IEEE CG&A 6(9), 1986).

PointLightBuffer, for the probe's light: a cube around the light, FACE_CELLS x FACE_CELLS
cells a face, lists for each cell, nearest first, the atoms whose cone of directions seen
from the light (half-angle asin(R / r) for radius R at distance r) meets the cell's cone.
DirectionalLightBuffer, for the sun: cells across the light, each listing the atoms whose
disc covers it. A pixel's ray tests its cell's list instead of walking the grid and stops
at the first atom beyond its end; culled atoms are left out and the ray is clipped as in
the walk, so the visibility is the walk's to the bit (shaders/light_buffer.glsl,
shaders/sun_buffer.glsl). The lists are built with numpy: filling them on the GPU, one
invocation per cell, took llvmpipe longer. docs/rendering.md gives the geometry.
"""

from __future__ import annotations

import numpy as np
from sasprobe.render.gl.buffers import upload
from sasprobe.render.gl.textures import table_image

# Cells along a cube face's edge: 6 × 8² = 384 lists (finer ones cost more to fill than they save).
FACE_CELLS = 8
ANGLE_MARGIN = 1e-4  # rad added to both cones: float32 lookups may land a cell off by rounding
RADIUS_MARGIN = 1e-3  # Å added to each atom's reach: float32 distances in the shader
# Å the light may move before the lists are built again, so a sliding probe rebuilds them
# every few frames: a ray from a light within SLACK of the lists' centre runs within R + SLACK
# of the centre's ray, so each atom's cone is taken about the centre with its radius grown by
# SLACK (wider cones, longer lists).
SLACK = 0.6
FACE_HALF = float(np.arccos(1.0 / np.sqrt(3.0)))  # rad: a cube face's cells lie within this
LEAD = 0.6  # of the slack: how far ahead of a moving light the lists are centred
# Å: the grid's candidates are gathered for a box this much wider than a build needs, and kept.
NEARBY_PAD = 2.0
IMAGE_LIST_SPHERES, IMAGE_LIST_ATOMS = 2, 3  # image units (shaders/light_buffer.glsl)


def cell_cones(face_cells: int = FACE_CELLS) -> np.ndarray:
    """(6 n², 4) float64: each cell's centre direction and the half-angle of the smallest
    cone about it holding the cell (its farthest corner: a cap is convex, so the farthest
    point of a cell, a spherical quadrilateral, is a corner). Cell id = (face n + j) n + i,
    face = 2 axis + (direction negative); i, j along the axes (axis+1) % 3 and (axis+2) % 3,
    as light_cell in shaders/light_buffer.glsl."""
    n = face_cells
    edges = np.linspace(-1.0, 1.0, n + 1)
    mids = 0.5 * (edges[:-1] + edges[1:])
    out = np.empty((6, n, n, 4))
    for face in range(6):
        jj, ii = np.meshgrid(np.arange(n), np.arange(n), indexing="ij")
        centre = _face_direction(face, mids[ii], mids[jj])
        half = np.zeros((n, n))
        for di in (0, 1):
            for dj in (0, 1):
                corner = _face_direction(face, edges[ii + di], edges[jj + dj])
                half = np.maximum(
                    half, np.arccos(np.clip(np.sum(corner * centre, axis=-1), -1.0, 1.0))
                )
        out[face, ..., :3] = centre
        out[face, ..., 3] = half
    return out.reshape(-1, 4)


def _face_direction(face: int, s, t) -> np.ndarray:
    """Unit directions through the points (s, t) of a cube face (as cell_cones numbers them)."""
    axis, sign = face // 2, (-1.0 if face % 2 else 1.0)
    v = np.zeros(np.broadcast(s, t).shape + (3,))
    v[..., axis] = sign
    v[..., (axis + 1) % 3] = s
    v[..., (axis + 2) % 3] = t
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


class PointLightBuffer:
    """The light buffer of one uploaded grid, rebuilt for each light it is asked for."""

    def __init__(self, gpu_grid, face_cells: int = FACE_CELLS, slack: float = SLACK):
        self.grid = gpu_grid
        self.slack = float(slack)
        self.ctx = gpu_grid.ctx
        self.face_cells = int(face_cells)
        self.n_cells = 6 * self.face_cells**2
        self.max_vdw = float(np.max(gpu_grid.vdw_radii, initial=0.0))
        cones = cell_cones(self.face_cells)
        half = np.minimum(cones[:, 3] + ANGLE_MARGIN, np.pi)
        self.cell_half = half
        cell_terms = np.column_stack([cones[:, :3], -np.cos(half), np.sin(half)]).astype(np.float32)
        self.face_terms = cell_terms.reshape(6, self.face_cells**2, 5)  # each face's cells
        # (lo, hi, atoms)
        self._nearby = (
            np.full(3, np.inf),
            np.full(3, -np.inf),
            np.empty(0, dtype=np.int64),
        )
        # Cell c lists entries starts[c] .. starts[c + 1]
        self.starts = np.zeros(self.n_cells + 1, dtype=np.int32)
        self.list_spheres = table_image(self.ctx, None, np.zeros((1, 4), dtype=np.float32))
        # The starts, then the entries' atoms
        self.list_atoms = table_image(self.ctx, None, self.starts, "i4")
        self.key: tuple | None = None
        self.centre = np.zeros(3)  # where the lists were built for
        self.last_position = np.zeros(3)  # the light the lists were last asked for
        self.reach = 0.0  # and how far their rays reach
        self.builds = 0
        self.atoms_in_reach = 0

    def build(self, position, reach: float, shell_outer: float) -> None:
        """Lists for a point light at `position` whose rays are at most `reach` Å long,
        occluders widened by `shell_outer` Å (the soft shell's outer offset; 0: hard)."""
        position = np.asarray(position, dtype=np.float64).reshape(3)
        shell_outer = max(float(shell_outer), 0.0)
        key = (shell_outer, self.grid.culling_version)
        moved, self.last_position = position - self.last_position, position
        if (
            key == self.key
            and reach <= self.reach
            and float(np.linalg.norm(position - self.centre)) <= self.slack
        ):
            return  # the lists hold for this light too
        # Centred ahead of a moving light (LEAD of the slack along its last step), the lists
        # hold while it crosses most of their ball, not only its radius.
        step = float(np.linalg.norm(moved))
        ahead = moved * (LEAD * self.slack / step) if 0.0 < step <= self.slack else 0.0
        # (the reach a little longer: it follows the ray origins' epsilon, which follows the light)
        self.key, self.centre, self.reach = key, position + ahead, float(reach) + RADIUS_MARGIN
        reach, position = self.reach, self.centre
        self.builds += 1
        grid = self.grid.grid
        pad = shell_outer + RADIUS_MARGIN + self.slack
        box = reach + self.max_vdw + pad
        atoms = self._candidates(position - box, position + box)
        atoms = atoms[~self.grid.culled_mask[atoms]]
        radii = self.grid.vdw_radii[atoms] + pad
        offset = grid.centers[atoms] - position
        distance = np.linalg.norm(offset, axis=1)
        near = distance - radii
        order = np.flatnonzero(near <= reach)
        order = order[np.argsort(near[order], kind="stable")]  # lists run nearest first
        atoms, radii, offset, distance = atoms[order], radii[order], offset[order], distance[order]
        self.atoms_in_reach = int(atoms.size)
        # Each atom's cone: the light inside the grown sphere sees it in every direction.
        inside = distance <= radii
        half = np.where(
            inside, np.pi, np.arcsin(np.minimum(radii / np.maximum(distance, 1e-30), 1.0))
        )
        half = np.minimum(half + ANGLE_MARGIN, np.pi)
        axes = offset / np.maximum(distance, 1e-30)[:, None]
        # Two cones meet when the angle between their axes is at most the sum a + b of their
        # half-angles: always once a + b >= pi, else when its cosine is at least
        # cos(a + b) = cos a cos b - sin a sin b, i.e. when (axis, -cos a, sin a) of the cell
        # dotted with (axis, cos b, sin b) of the atom is >= 0. Each face's cells are tested
        # only against the atoms whose cone meets the face's (its cells lie within FACE_HALF
        # of its axis): most atoms' cones are narrow and meet one face or two. (Products of
        # 64 x a few hundred x 5 stay on the calling thread in OpenBLAS, and `sasprobe` runs
        # it with one thread: its idle threads would spin after each.)
        # The margins hold float32
        atom_terms = np.column_stack([axes, np.cos(half), np.sin(half)]).astype(np.float32)
        near_face = np.cos(np.minimum(half + FACE_HALF + ANGLE_MARGIN, np.pi))
        wide = half + self.cell_half.max() >= np.pi  # a few at most, the light among them
        per_cell, entries = [], []
        for face in range(6):
            axis, sign = face // 2, (-1.0 if face % 2 else 1.0)
            slots = np.flatnonzero(sign * axes[:, axis] >= near_face)
            meets = self.face_terms[face] @ atom_terms[slots].T >= 0.0
            if wide.any():
                cells = slice(face * self.face_cells**2, (face + 1) * self.face_cells**2)
                meets |= (np.add.outer(self.cell_half[cells], half[slots]) >= np.pi) & wide[slots]
            cell, slot = np.nonzero(meets)  # by cell, then by slot: each list nearest first
            per_cell.append(np.bincount(cell, minlength=self.face_cells**2))
            entries.append(slots[slot])
        self.starts[0] = 0
        np.cumsum(np.concatenate(per_cell), out=self.starts[1:])
        listed = atoms[np.concatenate(entries)]
        if listed.size:
            self.list_spheres = table_image(
                self.ctx, self.list_spheres, self.grid.sphere_rows[listed]
            )
        self.list_atoms = table_image(
            self.ctx, self.list_atoms, np.concatenate([self.starts, listed]).astype(np.int32), "i4"
        )

    def _candidates(self, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
        """The atoms the grid stores in cells meeting the box [lo, hi]: those of a box
        NEARBY_PAD Å wider, kept while the boxes asked for stay within it (the light moves
        a few tenths of an Å between builds)."""
        near_lo, near_hi, atoms = self._nearby
        if np.any(lo < near_lo) or np.any(hi > near_hi):
            near_lo, near_hi = lo - NEARBY_PAD, hi + NEARBY_PAD
            atoms = self.grid.grid.candidates_in_box(near_lo, near_hi)
            self._nearby = (near_lo, near_hi, atoms)
        return atoms

    def bind(self) -> None:
        """The lists, for shaders/light_buffer.glsl."""
        self.list_spheres.bind_to_image(IMAGE_LIST_SPHERES, read=True, write=False)
        self.list_atoms.bind_to_image(IMAGE_LIST_ATOMS, read=True, write=False)

    def uniforms(self, shell_outer: float) -> dict[str, object]:
        return {
            "u_lb_face_cells": self.face_cells,
            "u_lb_cells": self.n_cells,
            "u_lb_centre": tuple(float(v) for v in self.centre),
            "u_lb_reach_pad": float(max(shell_outer, 0.0) + RADIUS_MARGIN + self.slack),
        }

    def counts(self) -> np.ndarray:
        """Each list's length (for tests and benchmarks)."""
        return np.diff(self.starts)

    def release(self) -> None:
        for obj in (self.list_spheres, self.list_atoms):
            obj.release()


# ------------------------------------------------------------------ the directional light
# Å: the directional buffer's cells across the light (finer: more entries, shorter lists)
SUN_CELL = 2.0
MAX_SUN_CELLS = 65535  # cell ids fit in uint16, which numpy sorts by radix
BINDING_SUN_START, IMAGE_SUN_SPHERES, IMAGE_SUN_ATOMS = 19, 6, 7  # shaders/sun_buffer.glsl


class DirectionalLightBuffer:
    """The directional light's shadow rays without the grid walk. Every ray runs parallel
    to the light, so it can only meet the atoms whose disc, seen along the light, holds the
    ray's own point there: a grid of SUN_CELL cells across the light lists, per cell, the
    kept atoms whose disc (vdW + the soft shell's outer offset + a margin) meets the cell,
    nearest the light first. A pixel's ray tests its cell's list and stops at the first atom
    wholly behind its origin (shaders/sun_buffer.glsl). The visibility is the minimum over
    the same occluders as the walk, with the same function: the walk's to the bit.

    Built on the CPU (numpy: the atoms sorted along the light once, their cells expanded and
    sorted by cell with a stable radix sort, which keeps that order in each cell) whenever
    the light direction, the shell or the culling changes."""

    def __init__(self, gpu_grid, cell: float = SUN_CELL):
        self.grid = gpu_grid
        self.ctx = gpu_grid.ctx
        self.cell = float(cell)
        self.starts = self.ctx.buffer(reserve=16)  # per cell, its first entry
        # the entries: tables in images (gl/textures.py table_image)
        self.spheres = table_image(self.ctx, None, np.zeros((1, 4), dtype=np.float32))
        self.atoms = table_image(self.ctx, None, np.zeros(1, dtype=np.int32), "i4")
        self.key: tuple | None = None
        self._uniforms: dict = {}
        self.entries = 0

    def build(self, towards_light, shell_outer: float) -> None:
        """Lists for a light in direction `towards_light` (unit, from the scene towards it),
        occluders widened by `shell_outer` Å (0: hard)."""
        d = np.asarray(towards_light, dtype=np.float64).reshape(3)
        shell_outer = max(float(shell_outer), 0.0)
        key = (d.tobytes(), shell_outer, self.grid.culling_version)
        if key == self.key:
            return
        self.key = key
        helper = np.eye(3)[int(np.argmin(np.abs(d)))]
        u = np.cross(d, helper)
        u /= np.linalg.norm(u)
        v = np.cross(d, u)
        pad = shell_outer + RADIUS_MARGIN
        atoms = np.flatnonzero(~self.grid.culled_mask)
        centres = self.grid.grid.centers[atoms]
        by_depth = np.argsort(-(centres @ d), kind="stable")  # nearest the light first
        atoms, centres = atoms[by_depth], centres[by_depth]
        vdw = self.grid.vdw_radii[atoms]
        reach = vdw + pad
        across = np.column_stack([centres @ u, centres @ v])
        if atoms.size:
            lo, hi = (across - reach[:, None]).min(axis=0), (across + reach[:, None]).max(axis=0)
        else:
            lo, hi = np.zeros(2), np.ones(2)
        cell = max(self.cell, float(np.sqrt(np.prod(hi - lo) / MAX_SUN_CELLS)) * 1.01)
        dims = np.maximum(np.ceil((hi - lo) / cell).astype(np.int64), 1)
        first = np.clip(
            np.floor((across - reach[:, None] - lo) / cell).astype(np.int64), 0, dims - 1
        )
        last = np.clip(
            np.floor((across + reach[:, None] - lo) / cell).astype(np.int64), 0, dims - 1
        )
        span = last - first + 1  # cells per atom along u and v
        per_atom = span[:, 0] * span[:, 1]
        owner = np.repeat(np.arange(atoms.size), per_atom)
        local = np.arange(owner.size) - np.repeat(np.cumsum(per_atom) - per_atom, per_atom)
        i = first[owner, 0] + local % span[owner, 0]
        j = first[owner, 1] + local // span[owner, 0]
        cell_id = (i + dims[0] * j).astype(np.uint16)
        order = np.argsort(cell_id, kind="stable")  # by cell, nearest the light first within one
        starts = np.zeros(int(dims[0] * dims[1]) + 1, dtype=np.uint32)
        np.cumsum(np.bincount(cell_id, minlength=starts.size - 1), out=starts[1:])
        listed = owner[order]
        upload(self.starts, starts)
        self.spheres = table_image(self.ctx, self.spheres, self.grid.sphere_rows[atoms[listed]])
        self.atoms = table_image(self.ctx, self.atoms, atoms[listed].astype(np.int32), "i4")
        self.entries = int(listed.size)
        self._uniforms = {
            "u_sb_u": tuple(u),
            "u_sb_v": tuple(v),
            "u_sb_origin": tuple(float(x) for x in lo),
            "u_sb_cell": float(cell),
            "u_sb_dims": tuple(int(x) for x in dims),
            "u_sb_behind": float(np.max(vdw, initial=0.0) + pad),
        }

    def bind(self) -> None:
        self.starts.bind_to_storage_buffer(BINDING_SUN_START)
        self.spheres.bind_to_image(IMAGE_SUN_SPHERES, read=True, write=False)
        self.atoms.bind_to_image(IMAGE_SUN_ATOMS, read=True, write=False)

    def uniforms(self) -> dict[str, object]:
        return dict(self._uniforms)

    def release(self) -> None:
        for obj in (self.starts, self.spheres, self.atoms):
            obj.release()
