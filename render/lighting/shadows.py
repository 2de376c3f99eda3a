"""Shadows traced per pixel through the grid: the directional light and the probe's point
light, hard or Parker soft, written as a visibility texture (r32f, 1 = lit) the light
pass multiplies in."""

from __future__ import annotations

from sasprobe.render.gl.compute import ComputePass
from sasprobe.render.gl.textures import texture_2d
from sasprobe.render.lighting.gbuffer import GBuffer
from sasprobe.render.lighting.settings import (
    HARD_SHADOW,
    DirectionalLight,
    PointLight,
    SoftShadow,
    light_uniforms,
    ray_epsilon_uniforms,
)


class ShadowPass(ComputePass):
    def __init__(self, gpu_grid):
        super().__init__(gpu_grid.ctx, "shadows.comp", gpu_grid)

    def trace(self, gbuffer: GBuffer, light: DirectionalLight | PointLight, soft: SoftShadow = HARD_SHADOW,
              out=None, rect=None, only_probe: bool = False):
        """Visibility texture (r32f) of `light` at every G-buffer pixel; `out` is reused when given.
        `rect` (x, y, width, height) traces only those pixels, `only_probe` only the probe's
        (the others keep what `out` holds)."""
        if soft.outer > self.grid.max_shell + 1e-9:
            raise ValueError(
                f"soft-shadow outer radius +{soft.outer:g} Å exceeds the grid's expansion "
                f"({self.grid.max_shell:g} Å, the probe radius): shells would be cut at cell borders"
            )
        width, height = gbuffer.size
        out = out or texture_2d(self.ctx, width, height)
        x, y, w, h = rect if rect is not None else (0, 0, width, height)
        gbuffer.bind()
        out.bind_to_image(0, read=False, write=True)
        point = isinstance(light, PointLight)
        self.run(w, h, {
            "u_offset": (int(x), int(y)),
            "u_only_probe": int(only_probe),
            **light_uniforms(None if point else light, light if point else None),
            "u_point_light": int(point),
            **ray_epsilon_uniforms(),
            "u_shell": soft.shell(),
            "u_shell_growth": float(soft.growth),
        })
        return out

