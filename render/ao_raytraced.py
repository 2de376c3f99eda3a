"""Ray-traced ambient occlusion through the grid (shaders/ao_raytraced.comp): cosine-weighted
rays of a set length, N per pixel per frame, accumulated while the view is still."""

from __future__ import annotations

from sasprobe.render.lighting_gbuffer import ComputePass, GBuffer, texture_2d
from sasprobe.render.lighting_params import ray_epsilon_uniforms


class RayTracedAO(ComputePass):
    def __init__(self, gpu_grid, seed: int = 1):
        super().__init__(gpu_grid.ctx, "ao_raytraced.comp", gpu_grid)
        self.seed = seed
        self.accumulated = None
        self.samples = 0

    def reset(self) -> None:
        """Forget the accumulated samples (the view, molecule, culling or probe changed)."""
        self.samples = 0

    def accumulate(self, gbuffer: GBuffer, spp: int, distance: float):
        """Add `spp` samples per pixel; returns the running-mean texture (r32f)."""
        width, height = gbuffer.size
        if self.accumulated is None or self.accumulated.size != (width, height):
            if self.accumulated is not None:
                self.accumulated.release()
            self.accumulated = texture_2d(self.ctx, width, height)
            self.samples = 0
        gbuffer.bind()
        self.accumulated.bind_to_image(0, read=True, write=True)
        self.run(width, height, {
            **ray_epsilon_uniforms(),
            "u_first_sample": self.samples,
            "u_spp": int(spp),
            "u_distance": float(distance),
            "u_seed": self.seed,
        })
        self.samples += int(spp)
        return self.accumulated

    def release(self) -> None:
        super().release()
        if self.accumulated is not None:
            self.accumulated.release()
