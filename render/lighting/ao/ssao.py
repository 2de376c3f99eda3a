"""Screen-space ambient occlusion (shaders/ao_ssao.comp): hemisphere point sampling or
Sculptor's line sampling, radius in Å, intensity, full or half resolution. Its output is
noisy and, at half resolution, small: the AO family (ao/__init__.py) follows it with the
bilateral blur (ao/blur.py), which also upsamples."""

from __future__ import annotations

from sasprobe.render.gl.compute import ComputeProgram
from sasprobe.render.gl.textures import texture_2d
from sasprobe.render.gl.uniforms import view_proj_uniforms
from sasprobe.render.lighting.gbuffer import GBuffer
from sasprobe.render.lighting.settings import AOSettings

SSAO_BIAS = 0.05  # Å: a sample must lie this far behind the visible surface to count


class SSAO(ComputeProgram):
    def __init__(self, ctx, seed: int = 3):
        super().__init__(ctx, "ao_ssao.comp")
        self.seed = seed

    @staticmethod
    def output_size(gbuffer: GBuffer, half_resolution: bool) -> tuple[int, int]:
        width, height = gbuffer.size
        return ((width + 1) // 2, (height + 1) // 2) if half_resolution else (width, height)

    def compute(self, gbuffer: GBuffer, view, proj, settings: AOSettings, out=None):
        width, height = self.output_size(gbuffer, settings.ssao_half_resolution)
        out = out or texture_2d(self.ctx, width, height)
        gbuffer.bind()
        out.bind_to_image(0, read=False, write=True)
        self.run(
            width,
            height,
            {
                **view_proj_uniforms(view, proj),
                "u_scale": 2 if settings.ssao_half_resolution else 1,
                "u_samples": int(settings.ssao_samples),
                "u_line_sampling": int(settings.ssao_sampling == "line"),
                "u_radius": float(settings.ssao_radius),
                "u_intensity": float(settings.ssao_intensity),
                "u_bias": SSAO_BIAS,
                "u_seed": self.seed,
            },
        )
        return out
