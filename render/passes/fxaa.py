"""Final pass: FXAA from the lit image to the output (or a plain copy when off)."""

from __future__ import annotations

from sasprobe.render.gl.uniforms import apply_uniforms
from sasprobe.render.passes.base import Frame, Pass


class FxaaPass(Pass):
    name = "fxaa"

    def __init__(self, ctx, programs):
        self.prog = programs.get("fullscreen.vert", "fxaa.frag")
        self.vao = ctx.vertex_array(self.prog, [])
        if "u_color" in self.prog:
            self.prog["u_color"].value = 0

    def run(self, frame: Frame) -> None:
        ctx, t = frame.ctx, frame.targets
        if not frame.scene.effects.fxaa:
            ctx.copy_framebuffer(frame.output_fbo, t.lit_fbo)
            return
        t.lit.use(0)
        w, h = frame.size
        apply_uniforms(self.prog, {"u_texel": (1.0 / w, 1.0 / h)})
        frame.output_fbo.use()
        frame.output_fbo.viewport = (0, 0, w, h)
        ctx.disable(ctx.DEPTH_TEST | ctx.BLEND)
        self.vao.render(ctx.TRIANGLES, vertices=3)

    def release(self) -> None:
        self.vao.release()
