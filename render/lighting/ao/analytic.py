"""Analytic sphere ambient occlusion (Quilez) from each atom's K nearest neighbours plus the
probe (shaders/ao_analytic.glsl). The neighbour lists (32 per atom, nearest first) are
computed once per molecule on the CPU through the grid and uploaded; K ≤ 32 is chosen per
frame. Cost per pixel is K sphere terms, independent of the molecule's size. On the
renderer's G-buffer it is drawn on the surfaces alone (render/gl/depth_picked.py); other
G-buffers are a compute pass."""

from __future__ import annotations

import numpy as np

from sasprobe.render.gl.compute import ComputePass
from sasprobe.render.gl.depth_picked import DepthPickedPass
from sasprobe.render.gl.textures import table_image, texture_2d
from sasprobe.render.lighting.gbuffer import GBuffer

MAX_K = 32  # matches ao_analytic.glsl
IMAGE_NEIGHBOURS = 1  # image unit (shaders/ao_analytic.glsl; the compute pass writes unit 0)


def nearest_to_point(centers: np.ndarray, point, k: int = MAX_K) -> np.ndarray:
    """The k atoms whose centres are nearest `point`, nearest first (-1 padded)."""
    diff = np.asarray(centers, dtype=np.float64) - np.asarray(point, dtype=np.float64)
    dist = np.einsum("ij,ij->i", diff, diff)
    take = min(k, dist.size)
    nearest = np.argpartition(dist, take - 1)[:take] if take < dist.size else np.arange(dist.size)
    nearest = nearest[np.lexsort((nearest, dist[nearest]))]
    out = np.full(k, -1, dtype=np.int64)
    out[:take] = nearest
    return out


class AnalyticAO(ComputePass):
    def __init__(self, gpu_grid):
        super().__init__(gpu_grid.ctx, "ao_analytic.comp", gpu_grid)
        neighbours, _ = gpu_grid.grid.nearest_neighbors(MAX_K)
        self.neighbours = neighbours  # (N, 32) int64, -1 padded
        self.table = table_image(self.ctx, None, neighbours.astype(np.int32).reshape(-1), "i4")
        self.probe_neighbours = np.full(MAX_K, -1, dtype=np.int64)
        self.drawn = DepthPickedPass(self.ctx, "ao_analytic.frag", gpu_grid)

    def update_probe(self) -> None:
        """Refresh the probe's neighbour list after the probe moved (GpuGrid.set_probe)."""
        probe = self.grid.probe_sphere
        self.probe_neighbours = (
            nearest_to_point(self.grid.grid.centers, probe[:3]) if probe[3] > 0 else np.full(MAX_K, -1, dtype=np.int64)
        )

    def compute(self, gbuffer: GBuffer, k: int, out=None):
        if not 1 <= k <= MAX_K:
            raise ValueError(f"analytic AO uses 1 to {MAX_K} neighbours, got {k}")
        width, height = gbuffer.size
        out = out or texture_2d(self.ctx, width, height)
        gbuffer.bind()
        self.table.bind_to_image(IMAGE_NEIGHBOURS, read=True, write=False)
        uniforms = {"u_k": int(k), "u_probe_neighbours": self.probe_neighbours.astype(np.int32).tobytes()}
        if gbuffer.depth is not None:
            self.drawn.run(out, gbuffer.depth, (0, 0, width, height), [((), ">")], uniforms, clear=1.0)
            return out
        out.bind_to_image(0, read=False, write=True)
        self.run(width, height, uniforms)
        return out

    def release(self) -> None:
        super().release()
        self.drawn.release()
        self.table.release()
