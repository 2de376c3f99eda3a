"""QuteMol's depth-aware contour lines and halos (shaders/edge_cueing.comp): a factor
texture (r32f, 1 = untouched) the final colour is multiplied by."""

from __future__ import annotations

from sasprobe.render.gl.compute import ComputeProgram
from sasprobe.render.gl.textures import texture_2d
from sasprobe.render.gl.uniforms import view_proj_uniforms
from sasprobe.render.lighting.gbuffer import GBuffer
from sasprobe.render.lighting.settings import EdgeCueing


class EdgeCueingProgram(ComputeProgram):
    def __init__(self, ctx):
        super().__init__(ctx, "edge_cueing.comp")

    def compute(self, gbuffer: GBuffer, view, proj, settings: EdgeCueing, out=None, rect=None):
        """The factor texture; `rect` (x, y, width, height) recomputes only those pixels of
        `out`."""
        width, height = gbuffer.size
        out = out or texture_2d(self.ctx, width, height)
        x, y, w, h = rect if rect is not None else (0, 0, width, height)
        gbuffer.bind()
        out.bind_to_image(0, read=False, write=True)
        self.run(
            w,
            h,
            {
                "u_offset": (int(x), int(y)),
                **view_proj_uniforms(view, proj),
                "u_contours": int(settings.contours),
                "u_line_width": float(settings.line_width),
                "u_line_threshold": float(settings.line_threshold),
                "u_halos": int(settings.halos),
                "u_halo_radius": float(settings.halo_radius),
                "u_halo_depth": float(settings.halo_depth),
                "u_halo_strength": float(settings.halo_strength),
            },
        )
        return out
