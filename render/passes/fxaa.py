"""Final pass: FXAA from the lit image to the output (or a plain copy when off).

With the frame cache the antialiased picture is kept, and a frame whose lit picture
changed only in a rectangle (Frame.lit_changed, with the probe's cues of this frame and
the last, Frame.overlay) runs FXAA again only there, grown by the shader's reach; the
kept picture is then copied to the output."""

from __future__ import annotations

from sasprobe.render.frame_cache import Rect, full_rect, grow_rect, union_rect
from sasprobe.render.gl.targets import KeptPicture
from sasprobe.render.gl.uniforms import apply_uniforms
from sasprobe.render.passes.base import WHOLE, Frame, Pass

# How far from a pixel shaders/fxaa.frag reads: its taps lie up to SPAN_MAX / 2 = 4 pixels
# away, read bilinearly (one more), and its diagonal neighbours; one pixel to spare.
FXAA_REACH_PX = 6


class FxaaPass(Pass):
    name = "fxaa"

    def __init__(self, ctx, programs):
        self.prog = programs.get("fullscreen.vert", "fxaa.frag")
        self.vao = ctx.vertex_array(self.prog, [])
        if "u_color" in self.prog:
            self.prog["u_color"].value = 0
        self._kept = KeptPicture(ctx)  # the antialiased picture kept across frames (frame cache)
        self._kept_holds = False  # it holds the last frame's output
        self._last_overlay: Rect | None = None
        self.redone: Rect | None = None  # what the last frame ran FXAA over (None: nothing)

    def run(self, frame: Frame) -> None:
        ctx, t = frame.ctx, frame.targets
        if not frame.scene.effects.fxaa:
            ctx.copy_framebuffer(frame.output_fbo, t.lit_fbo)
            self._kept_holds = False
            return
        target, self.redone = frame.output_fbo, full_rect(frame.size)
        self._kept_holds = self._kept_holds and frame.cache is not None  # a frame drawn whole leaves it behind
        if frame.cache is not None:
            target = self._kept.framebuffer(frame.size)
            self.redone = self._to_redo(frame)
        if self.redone is not None:
            t.lit.use(0)
            w, h = frame.size
            apply_uniforms(self.prog, {"u_texel": (1.0 / w, 1.0 / h)})
            target.use()
            target.viewport = (0, 0, w, h)
            target.scissor = self.redone
            ctx.disable(ctx.DEPTH_TEST | ctx.BLEND)
            self.vao.render(ctx.TRIANGLES, vertices=3)
            target.scissor = None
        if target is not frame.output_fbo:
            ctx.copy_framebuffer(frame.output_fbo, target)

    def _to_redo(self, frame: Frame) -> Rect | None:
        """Where the lit picture changed since the last frame (its cues there too: they are
        drawn over a fresh copy each frame), grown by FXAA's reach; all of it when the kept
        picture does not hold the last frame's output."""
        last_overlay, self._last_overlay = self._last_overlay, frame.overlay
        holds, self._kept_holds = self._kept_holds and not self._kept.fresh, True
        if not holds or frame.lit_changed == WHOLE:
            return full_rect(frame.size)
        changed = union_rect(frame.lit_changed, union_rect(frame.overlay, last_overlay))
        return grow_rect(changed, FXAA_REACH_PX, frame.size)

    def release(self) -> None:
        self.vao.release()
        self._kept.release()
