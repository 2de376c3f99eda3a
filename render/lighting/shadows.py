"""Shadows traced per pixel through the grid: the directional light and the probe's point
light, hard or Parker soft, written as a visibility texture (r32f, 1 = lit) the light
pass multiplies in. The point light's rays go through its light buffer
(render/lighting/light_buffer.py), rebuilt when the light moves beyond its slack; the same
visibility as the grid walk, which `light_buffer=False` keeps (tests, benchmarks).

On the renderer's G-buffer, which has a depth buffer, the trace is drawn (shaders/shadows.frag)
over the surfaces a depth test picks, the rest cleared to 1: llvmpipe skips the blocks of
pixels a depth test rejects, and would run the trace's code for background pixels of a
compute pass. Other G-buffers (uploaded, ray cast) and the probe's own pixels are traced by
shaders/shadows.comp."""

from __future__ import annotations

import numpy as np
from sasprobe.render.gl.compute import ComputeVariants
from sasprobe.render.gl.depth_picked import DepthPickedDraw
from sasprobe.render.gl.textures import texture_2d
from sasprobe.render.lighting.gbuffer import GBuffer
from sasprobe.render.lighting.light_buffer import FACE_CELLS, PointLightBuffer
from sasprobe.render.lighting.settings import (
    HARD_SHADOW,
    RAY_EPS_ABS,
    RAY_EPS_REL,
    DirectionalLight,
    PointLight,
    SoftShadow,
    light_uniforms,
    ray_epsilon_uniforms,
)


class ShadowTracer:
    """Shadows of one uploaded grid. shaders/shadows.comp is compiled per case (the walk or the
    light buffer; with or without clipping), each program holding only its own code."""

    def __init__(self, gpu_grid, light_buffer: bool = True, face_cells: int = FACE_CELLS):
        self.ctx = gpu_grid.ctx
        self.grid = gpu_grid
        self.light_buffer = PointLightBuffer(gpu_grid, face_cells) if light_buffer else None
        # The grid's own: shared with the occlusion atlas.
        self.sun_buffer = gpu_grid.sun_buffer() if light_buffer else None
        self.programs = ComputeVariants(self.ctx, "shadows.comp", gpu_grid)
        self.drawn = DepthPickedDraw(self.ctx, "shadows.frag", gpu_grid)  # on the renderer's

    def trace(
        self,
        gbuffer: GBuffer,
        light: DirectionalLight | PointLight,
        soft: SoftShadow = HARD_SHADOW,
        out=None,
        rect=None,
        only_probe: bool = False,
        all_cuts: bool = False,
    ):
        """Visibility texture (r32f) of `light` at every G-buffer pixel; `out` is reused when given.
        `rect` (x, y, width, height) traces only those pixels, `only_probe` only the probe's
        (the others keep what `out` holds). `all_cuts` clips a point light's rays by every
        cut, as the probe's own pixels are (see `prepared`)."""
        width, height = gbuffer.size
        out = out or texture_2d(self.ctx, width, height)
        x, y, w, h = rect if rect is not None else (0, 0, width, height)
        cases, uniforms = self.prepared(light, soft, from_kept_points=not (only_probe or all_cuts))
        gbuffer.bind()
        if gbuffer.depth is not None and not only_probe:  # 1 on the background, the surfaces traced
            self.drawn.run(out, gbuffer.depth, (x, y, w, h), [(cases, ">")], uniforms, clear=1.0)
            return out
        out.bind_to_image(0, read=False, write=True)
        self.programs.get(*cases).run(
            w, h, {**uniforms, "u_offset": (int(x), int(y)), "u_only_probe": int(only_probe)}
        )
        return out

    def prepared(
        self,
        light: DirectionalLight | PointLight,
        soft: SoftShadow = HARD_SHADOW,
        from_kept_points: bool = True,
    ) -> tuple[tuple, dict]:
        """The light's buffer built and bound, and what a program tracing it per pixel with
        shaders/light_visibility.glsl takes: its cases (#defines, as ComputeVariants.get
        takes them) and uniforms (the grid's besides, which these override; the grid is
        bound by the caller). A point light's rays are clipped only by the cuts it lies
        beyond (Culling.cuts_before) when they start from kept points (`from_kept_points`:
        the drawn surfaces; not the probe's own, which may lie outside the cube): the
        others cannot shorten a segment between two kept points, and on llvmpipe every cut
        tested costs each pixel its instructions."""
        if soft.outer > self.grid.max_shell + 1e-9:
            raise ValueError(
                f"soft-shadow outer radius +{soft.outer:g} Å exceeds the grid's expansion "
                f"({self.grid.max_shell:g} Å, the probe radius): "
                "shells would be cut at cell borders"
            )
        point = isinstance(light, PointLight)
        buffered = point and self.light_buffer is not None
        sun_buffered = not point and self.sun_buffer is not None
        buffer_uniforms = {}
        if buffered:
            self.light_buffer.build(
                light.position, light.radius + self._origin_slack(light), soft.outer
            )
            self.light_buffer.bind()
            buffer_uniforms = self.light_buffer.uniforms(soft.outer)
        if sun_buffered:
            self.sun_buffer.build(light.unit(), soft.outer)
            self.sun_buffer.bind()
            buffer_uniforms = self.sun_buffer.uniforms()
        culling = self.grid.culling
        if point and from_kept_points:
            culling = culling.cuts_before(light.position)
        cases = (
            ("LIGHT_BUFFER", buffered),
            ("SUN_BUFFER", sun_buffered),
            ("NO_CLIPPING", not culling.clipping),
            ("NO_CUBE", culling.nav_cube is None),
            ("HARD_SHADOWS", soft == HARD_SHADOW),
        )
        uniforms = {
            **culling.uniforms(),
            **buffer_uniforms,
            **light_uniforms(None if point else light, light if point else None),
            "u_point_light": int(point),
            **ray_epsilon_uniforms(),
            "u_shell": soft.shell(),
            "u_shell_growth": float(soft.growth),
        }
        return cases, uniforms

    def bind(self) -> None:
        """The buffers `prepared` built, bound again (the grid's, and the light buffer's)."""
        self.grid.bind()
        if self.light_buffer is not None:
            self.light_buffer.bind()

    def _origin_slack(self, light: PointLight) -> float:
        """How much farther than its radius from the light a ray origin can lie: pixels are
        traced within the radius, and their rays start a ray epsilon off the surface."""
        return RAY_EPS_ABS + RAY_EPS_REL * (float(np.max(np.abs(light.position))) + light.radius)

    def release(self) -> None:
        self.programs.release()
        self.drawn.release()
        if self.light_buffer is not None:
            self.light_buffer.release()
