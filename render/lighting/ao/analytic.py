"""Analytic sphere ambient occlusion (Quilez) from each atom's K nearest neighbours plus the
probe (shaders/ao_analytic.glsl). The neighbour lists (32 per atom, nearest first) are
found on the CPU through the grid for the atoms a G-buffer can show (the renderer's: the
atoms drawn as spheres, in the workspace view the cube's), each once per molecule, and
uploaded row by row; K ≤ 32 is chosen per frame. Cost per pixel is K sphere terms,
independent of the molecule's size. On the renderer's G-buffer it is drawn on the
surfaces alone (render/gl/depth_picked.py); other G-buffers are a compute pass."""

from __future__ import annotations

import numpy as np
from sasprobe.render.gl.compute import ComputeProgram
from sasprobe.render.gl.depth_picked import DepthPickedDraw
from sasprobe.render.gl.textures import TABLE_ROW, table_rows, texture_2d, write_table_rows
from sasprobe.render.lighting.gbuffer import GBuffer

MAX_K = 32  # matches ao_analytic.glsl
IMAGE_NEIGHBOURS = 1  # image unit (shaders/ao_analytic.glsl; the compute pass writes unit 0)


def nearest_to_point(centers: np.ndarray, point, k: int = MAX_K) -> np.ndarray:
    """The k atoms whose centres are nearest `point`, nearest first (-1 padded), by brute
    force (UniformGrid.nearest_to_point finds the same through the grid)."""
    diff = np.asarray(centers, dtype=np.float64) - np.asarray(point, dtype=np.float64)
    dist = np.einsum("ij,ij->i", diff, diff)
    take = min(k, dist.size)
    nearest = np.argpartition(dist, take - 1)[:take] if take < dist.size else np.arange(dist.size)
    nearest = nearest[np.lexsort((nearest, dist[nearest]))]
    out = np.full(k, -1, dtype=np.int64)
    out[:take] = nearest
    return out


class AnalyticAO(ComputeProgram):
    def __init__(self, gpu_grid):
        super().__init__(gpu_grid.ctx, "ao_analytic.comp", gpu_grid)
        n = gpu_grid.n_atoms
        # The lists found so far, -1 padded
        self.neighbours = np.full((n, MAX_K), -1, dtype=np.int32)
        self.found = np.zeros(n, dtype=bool)
        # a table image (textures.table_image's layout), written row by row as lists are found
        self.table = texture_2d(self.ctx, TABLE_ROW, table_rows(n * MAX_K), 1, "i4")
        self.probe_neighbours = np.full(MAX_K, -1, dtype=np.int64)
        self.drawn = DepthPickedDraw(self.ctx, "ao_analytic.frag", gpu_grid)

    def find(self, atoms: np.ndarray | None = None) -> None:
        """The neighbour lists of `atoms` (None: every atom) on the GPU, found where not yet."""
        missing = (
            np.flatnonzero(~self.found)
            if atoms is None
            else np.unique(np.asarray(atoms, dtype=np.int64)[~self.found[atoms]])
        )
        if missing.size == 0:
            return
        self.neighbours[missing] = self.grid.grid.nearest_neighbors(MAX_K, of=missing)[0]
        self.found[missing] = True
        entries = (
            missing[:, None] * MAX_K + np.array([0, MAX_K - 1])
        ).ravel()  # a list's first and last
        write_table_rows(self.table, self.neighbours.reshape(-1), entries)

    def update_probe(self) -> None:
        """Refresh the probe's neighbour list after the probe moved (UploadedGrid.set_probe)."""
        probe = self.grid.probe_sphere
        self.probe_neighbours = (
            self.grid.grid.nearest_to_point(probe[:3], MAX_K)
            if probe[3] > 0
            else np.full(MAX_K, -1, dtype=np.int64)
        )

    def compute(
        self, gbuffer: GBuffer, k: int, out=None, atoms: np.ndarray | None = None, rect=None
    ):
        """The accessibility of the G-buffer's pixels; `atoms`: those it can show (None: any);
        `rect`: only there, 1 elsewhere (the renderer's G-buffer; None: everywhere)."""
        if not 1 <= k <= MAX_K:
            raise ValueError(f"analytic AO uses 1 to {MAX_K} neighbours, got {k}")
        self.find(atoms)
        width, height = gbuffer.size
        out = out or texture_2d(self.ctx, width, height)
        gbuffer.bind()
        self.table.bind_to_image(IMAGE_NEIGHBOURS, read=True, write=False)
        uniforms = {
            "u_k": int(k),
            "u_probe_neighbours": self.probe_neighbours.astype(np.int32).tobytes(),
        }
        if gbuffer.depth is not None:
            whole = (0, 0, width, height)
            if rect is not None and tuple(rect) != whole:
                # 1 beyond the rectangle
                self.drawn.run(out, gbuffer.depth, whole, [], uniforms, clear=1.0)
            self.drawn.run(
                out,
                gbuffer.depth,
                whole if rect is None else rect,
                [((), ">")],
                uniforms,
                clear=1.0,
            )
            return out
        out.bind_to_image(0, read=False, write=True)
        self.run(width, height, uniforms)
        return out

    def release(self) -> None:
        super().release()
        self.drawn.release()
        self.table.release()
