"""The first pass: background values in the G-buffer (depth 1, atom id ATOM_BACKGROUND)
and a visibility of 1 everywhere."""

from __future__ import annotations

from sasprobe.render.gl.programs import ProgramCache
from sasprobe.render.passes.base import MOLECULE, Frame, Pass


class ClearPass(Pass):
    """The G-buffer cleared to the background, the visibility buffer to 1."""

    name = "clear"
    layer = MOLECULE

    def __init__(self, ctx, programs: ProgramCache):
        self.prog = programs.get("fullscreen.vert", "gbuffer_clear.frag")
        self.vao = ctx.vertex_array(self.prog, [])

    def run(self, frame: Frame) -> None:
        # A clear is a fill of each tile; a full-screen draw runs a shader per pixel, so it
        # writes only what a clear cannot: the ids' -1.
        t = frame.targets
        t.gbuffer_fbo.use()
        t.gbuffer_fbo.clear(0.0, 0.0, 0.0, 0.0, depth=1.0)  # the ids too, drawn over below
        t.ids_fbo.use()
        frame.ctx.disable(frame.ctx.DEPTH_TEST | frame.ctx.BLEND)
        self.vao.render(frame.ctx.TRIANGLES, vertices=3)
        t.clear_visibility()

    def release(self) -> None:
        self.vao.release()

