"""QuteMol's depth-aware contour lines and halos (shaders/edge_cueing.comp): a factor
texture (r32f, 1 = untouched) the final colour is multiplied by."""

from __future__ import annotations

from dataclasses import dataclass

from sasprobe.render.ao_ssao import camera_uniforms
from sasprobe.render.lighting_gbuffer import ComputePass, GBuffer, texture_2d


@dataclass(frozen=True)
class EdgeCueing:
    contours: bool = True
    halos: bool = False
    line_width: float = 1.5  # pixels
    line_threshold: float = 1.5  # Å of depth jump where lines start (full at twice that)
    halo_radius: float = 8.0  # pixels
    halo_depth: float = 6.0  # Å of depth gap for a full halo
    halo_strength: float = 0.6

    def __post_init__(self) -> None:
        for name in ("line_width", "line_threshold", "halo_radius", "halo_depth"):
            if not getattr(self, name) > 0:
                raise ValueError(f"edge cueing {name} must be positive")
        if not 0.0 <= self.halo_strength <= 1.0:
            raise ValueError("halo strength must lie in [0, 1]")


class EdgeCueingPass(ComputePass):
    def __init__(self, ctx):
        super().__init__(ctx, "edge_cueing.comp")

    def compute(self, gbuffer: GBuffer, view, proj, settings: EdgeCueing, out=None):
        width, height = gbuffer.size
        out = out or texture_2d(self.ctx, width, height)
        gbuffer.bind()
        out.bind_to_image(0, read=False, write=True)
        self.run(width, height, {
            **camera_uniforms(view, proj),
            "u_contours": int(settings.contours),
            "u_line_width": float(settings.line_width),
            "u_line_threshold": float(settings.line_threshold),
            "u_halos": int(settings.halos),
            "u_halo_radius": float(settings.halo_radius),
            "u_halo_depth": float(settings.halo_depth),
            "u_halo_strength": float(settings.halo_strength),
        })
        return out
