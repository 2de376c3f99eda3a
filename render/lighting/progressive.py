"""Monte-Carlo passes that accumulate a running mean over frames while the view is still
(ray-traced AO, path tracing). The shader adds `u_spp` samples to the `u_first_sample`
already averaged in the image at binding 0, sample i of each pixel being the i-th point of
its R2 sequence (shaders/sampling.glsl), so splitting the samples over frames changes
nothing but the order they arrive in."""

from __future__ import annotations

from sasprobe.render.gl.compute import ComputeProgram
from sasprobe.render.gl.textures import texture_2d
from sasprobe.render.lighting.gbuffer import GBuffer


class ProgressiveProgram(ComputeProgram):
    components = 1  # of the accumulated image

    def __init__(self, gpu_grid, shader: str, seed: int = 1):
        super().__init__(gpu_grid.ctx, shader, gpu_grid)
        self.seed = seed
        self.accumulated = None
        self.samples = 0

    def reset(self) -> None:
        """Forget the accumulated samples (the view, molecule, culling or lights changed)."""
        self.samples = 0

    def add_samples(self, gbuffer: GBuffer, spp: int, uniforms: dict):
        width, height = gbuffer.size
        if self.accumulated is None or self.accumulated.size != (width, height):
            if self.accumulated is not None:
                self.accumulated.release()
            self.accumulated = texture_2d(self.ctx, width, height, self.components)
            self.samples = 0
        gbuffer.bind()
        self.accumulated.bind_to_image(0, read=True, write=True)
        self.run(
            width,
            height,
            {**uniforms, "u_first_sample": self.samples, "u_spp": int(spp), "u_seed": self.seed},
        )
        self.samples += int(spp)
        return self.accumulated

    def release(self) -> None:
        super().release()
        if self.accumulated is not None:
            self.accumulated.release()
