"""The first pass: background values in the G-buffer (depth 1, atom id ATOM_BACKGROUND)
and a visibility of 1 everywhere; on a frame that keeps the trace and redraws the atoms
(FramePlan.context_kept) only the atoms' pixels, those whose ray meets the navigation cube
(shaders/gbuffer_clear.frag CUBE_WINDOW), within the plan's rectangle."""

from __future__ import annotations

from sasprobe.render.gl.programs import ProgramCache
from sasprobe.render.gl.uniforms import apply_uniforms
from sasprobe.render.passes.backbone import cube_uniforms
from sasprobe.render.passes.base import Frame, Layer, Pass


class ClearPass(Pass):
    """The G-buffer cleared to the background, the visibility buffer to 1."""

    name = "clear"
    layer = Layer.MOLECULE

    def __init__(self, ctx, programs: ProgramCache):
        self.prog = programs.get("fullscreen.vert", "gbuffer_clear.frag")
        self.vao = ctx.vertex_array(self.prog, [])
        self.window = ctx.vertex_array(
            programs.get("fullscreen.vert", "gbuffer_clear.frag", defines=("CUBE_WINDOW",)), []
        )

    def run(self, frame: Frame) -> None:
        t, ctx = frame.targets, frame.ctx
        if frame.plan.context_kept:
            self._clear_atoms(frame)
            return
        # A clear is a fill of each tile; a full-screen draw runs a shader per pixel, so it
        # writes only what a clear cannot: the ids' -1.
        t.gbuffer_fbo.use()
        t.gbuffer_fbo.clear(0.0, 0.0, 0.0, 0.0, depth=1.0)  # the ids too, drawn over below
        t.ids_fbo.use()
        ctx.disable(ctx.DEPTH_TEST | ctx.BLEND)
        self.vao.render(ctx.TRIANGLES, vertices=3)
        t.clear_visibility()

    def _clear_atoms(self, frame: Frame) -> None:
        t, ctx, rect = frame.targets, frame.ctx, frame.plan.redraw
        if rect is None:
            return
        apply_uniforms(
            self.window.program, {**frame.raster_camera_uniforms(), **cube_uniforms(frame.cube)}
        )
        t.gbuffer_fbo.use()
        t.gbuffer_fbo.scissor = rect
        ctx.enable_only(ctx.DEPTH_TEST)
        ctx.depth_func = "1"  # written whatever it held
        try:
            self.window.render(ctx.TRIANGLES, vertices=3)
        finally:
            ctx.depth_func = "<"
            t.gbuffer_fbo.scissor = None
        t.visibility_fbo.use()
        t.visibility_fbo.clear(1.0, 1.0, 1.0, 1.0, viewport=rect)

    def release(self) -> None:
        self.vao.release()
        self.window.release()
