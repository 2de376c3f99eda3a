"""G-buffer pass of the backbone trace: C-alpha (P) segments per chain, chain-coloured,
shaded as thin tubes, outside the navigation cube only (inside it the spheres show
the atoms), and nowhere over the cube's projection, so context never hides the work
(the cube is a window: only what is in it shows through it). Drawn when a navigation
cube is in effect, or always with `show_always`."""

from __future__ import annotations

import numpy as np
from sasprobe.protocol.view import TRACE_MIN_PX as MIN_WIDTH_PX
from sasprobe.protocol.view import TRACE_RADIUS
from sasprobe.render.gl.buffers import BACKBONE_FORMAT
from sasprobe.render.gl.uniforms import apply_planes, apply_uniforms
from sasprobe.render.passes.base import Frame, Layer, Pass


class BackbonePass(Pass):
    name = "backbone"
    layer = Layer.CONTEXT

    def __init__(self, ctx, programs, buffers, show_always: bool = False):
        self.prog = programs.get("backbone.vert", "backbone.frag", "wide_line.geom")
        self.vao = ctx.vertex_array(
            self.prog, [(buffers.backbone, BACKBONE_FORMAT, "in_position", "in_color", "in_atom")]
        )
        self.n_vertices = buffers.n_backbone_vertices
        self.show_always = show_always

    def state(self):
        return self.show_always

    def enabled(self, frame: Frame) -> bool:
        return (
            self.n_vertices > 0
            and frame.scene.effects.backbone
            and (frame.cube is not None or self.show_always)
        )

    def run(self, frame: Frame) -> None:
        ctx = frame.ctx
        apply_uniforms(self.prog, frame.raster_camera_uniforms())
        apply_uniforms(self.prog, line_width_uniforms(frame, TRACE_RADIUS, MIN_WIDTH_PX))
        # The probe plane cuts atoms: the trace never hides the probe
        apply_planes(self.prog, frame.context_planes)
        apply_uniforms(self.prog, cube_uniforms(frame.cube))
        apply_uniforms(
            self.prog, {"u_cube_enabled": int(frame.cube is not None), "u_cube_window": 1}
        )
        frame.targets.gbuffer_fbo.use()
        ctx.enable_only(ctx.DEPTH_TEST)
        ctx.depth_func = "<"
        self.vao.render(ctx.LINES, vertices=self.n_vertices)

    def release(self) -> None:
        self.vao.release()


def cube_uniforms(cube) -> dict:
    """The navigation cube as shaders take it: u_cube (centre, half edge) and u_cube_axes."""
    if cube is None:
        return {
            "u_cube": (0.0, 0.0, 0.0, 0.0),
            "u_cube_axes": np.eye(3, dtype=np.float32).tobytes(),
        }
    # Column-major
    return {
        "u_cube": (*map(float, cube.center), float(cube.half)),
        "u_cube_axes": np.ascontiguousarray(cube.axes.T, dtype=np.float32).tobytes(),
    }


def line_width_uniforms(frame: Frame, radius: float, min_width_px: float) -> dict:
    """Uniforms of shaders/wide_line.geom."""
    return {
        "u_radius": float(radius),
        "u_min_width_px": float(min_width_px),
        "u_proj_scale": float(frame.proj[1, 1]) * frame.size[1] * 0.5,
    }
