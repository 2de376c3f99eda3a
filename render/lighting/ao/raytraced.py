"""Ray-traced ambient occlusion through the grid (shaders/ao_raytraced.comp): cosine-weighted
rays of a set length, N per pixel per frame, accumulated while the view is still."""

from __future__ import annotations

from sasprobe.render.lighting.gbuffer import GBuffer
from sasprobe.render.lighting.progressive import ProgressiveProgram
from sasprobe.render.lighting.settings import ray_epsilon_uniforms


class RayTracedAO(ProgressiveProgram):
    def __init__(self, gpu_grid, seed: int = 1):
        super().__init__(gpu_grid, "ao_raytraced.comp", seed)

    def accumulate(self, gbuffer: GBuffer, spp: int, distance: float):
        """Add `spp` samples per pixel; returns the running-mean texture (r32f)."""
        return self.add_samples(
            gbuffer, spp, {**ray_epsilon_uniforms(), "u_distance": float(distance)}
        )
