"""Depth- and normal-aware bilateral blur (shaders/bilateral_blur.comp) of noisy
accessibility, and joint-bilateral upsampling of half-resolution input."""

from __future__ import annotations

from sasprobe.render.gl.compute import ComputeProgram
from sasprobe.render.gl.textures import texture_2d
from sasprobe.render.gl.uniforms import view_proj_uniforms
from sasprobe.render.lighting.gbuffer import GBuffer


class BilateralBlur(ComputeProgram):
    def __init__(self, ctx, radius: int = 4, sigma: float = 2.5, depth_sigma: float = 0.02):
        super().__init__(ctx, "bilateral_blur.comp")
        self.radius, self.sigma, self.depth_sigma = radius, sigma, depth_sigma

    def apply(self, gbuffer: GBuffer, view, proj, source, out=None):
        """Full-resolution blurred copy of `source` (G-buffer size, or half of it)."""
        width, height = gbuffer.size
        scale = 1 if source.size == (width, height) else 2
        out = out or texture_2d(self.ctx, width, height)
        gbuffer.bind()
        source.use(location=3)
        out.bind_to_image(0, read=False, write=True)
        self.run(
            width,
            height,
            {
                **view_proj_uniforms(view, proj),
                "u_scale": scale,
                "u_radius": max(1, self.radius // scale),
                "u_sigma": self.sigma / scale,
                "u_depth_sigma": self.depth_sigma,
            },
        )
        return out
