"""Forward pass: the navigation cube's 12 edges over the lit image, depth-tested
against the G-buffer (hidden where atoms are in front)."""

from __future__ import annotations

import itertools

import numpy as np
from sasprobe.molecule.colors import CUBE_WIRE_COLOR
from sasprobe.protocol.view import WIRE_PX as WIRE_WIDTH_PX
from sasprobe.render.gl.uniforms import apply_uniforms
from sasprobe.render.passes.backbone import cube_uniforms, line_width_uniforms
from sasprobe.render.passes.base import Frame, Pass

WIRE_COLOR = (*CUBE_WIRE_COLOR, 1.0)


def cube_edges() -> np.ndarray:
    """(24, 3) float32: the 12 edges of [-1, 1]^3 as line-list endpoints."""
    corners = np.array(list(itertools.product((-1.0, 1.0), repeat=3)))
    edges = [
        (a, b)
        for a, b in itertools.combinations(range(8), 2)
        if np.sum(corners[a] != corners[b]) == 1
    ]
    return corners[np.array(edges).reshape(-1)].astype(np.float32)


class NavCubePass(Pass):
    name = "navcube"

    def __init__(self, ctx, programs):
        self.prog = programs.get("cube.vert", "cube.frag", "wide_line.geom")
        self.vbo = ctx.buffer(cube_edges().tobytes())
        self.vao = ctx.vertex_array(self.prog, [(self.vbo, "3f", "in_position")])

    def enabled(self, frame: Frame) -> bool:
        return frame.scene.nav_cube is not None and frame.scene.effects.cube_wire

    def run(self, frame: Frame) -> None:
        ctx, cube = frame.ctx, frame.scene.nav_cube
        apply_uniforms(self.prog, frame.raster_camera_uniforms())
        apply_uniforms(self.prog, line_width_uniforms(frame, 0.0, WIRE_WIDTH_PX))
        apply_uniforms(self.prog, cube_uniforms(cube))
        apply_uniforms(self.prog, {"u_wire_color": WIRE_COLOR})
        fbo = frame.targets.lit_fbo
        fbo.use()
        ctx.enable_only(ctx.DEPTH_TEST)
        ctx.depth_func = "<="
        # Tested against, never written: the G-buffer's depth outlives the frame (frame cache).
        fbo.depth_mask = False
        try:
            self.vao.render(ctx.LINES, vertices=24)
        finally:
            fbo.depth_mask = True

    def release(self) -> None:
        self.vao.release()
        self.vbo.release()
