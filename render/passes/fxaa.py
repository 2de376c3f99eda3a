"""Final pass: FXAA from the lit image to the output (or a plain copy when off).

On layered frames the antialiased picture is kept and FXAA runs again over the plan's
regions grown by the shader's reach: whole over the changed background and the probe's cues
(OVERLAY), and over the changed surfaces (LIT) only near a surface (NearSurfaces), since the
pixels farther away read nothing but background, which did not change.
"""

from __future__ import annotations

from sasprobe.render.frame_planner import LIT, LIT_BACKGROUND, OVERLAY
from sasprobe.render.gl.depth_picked import DepthTestedTarget
from sasprobe.render.gl.textures import release_framebuffers
from sasprobe.render.gl.uniforms import apply_uniforms
from sasprobe.render.passes.base import Frame, Pass
from sasprobe.render.rects import Rect, full_rect, grow_rect, subtract_rect, union_rect

# How far from a pixel shaders/fxaa.frag reads: its taps lie up to SPAN_MAX / 2 = 4 pixels
# away, read bilinearly (one more), and its diagonal neighbours; one pixel to spare.
FXAA_REACH_PX = 6


class NearSurfaces:
    """A depth texture of the frame: 0 within FXAA_REACH_PX pixels of a G-buffer surface,
    1 elsewhere (shaders/near_surfaces.frag), made when a frame asks and kept for the
    molecule layer it was made from (FramePlan.layer_version). Made from a frame with the
    probe drawn in, it also marks what lies around that probe: a wider mask, never a
    narrower one."""

    def __init__(self, ctx, programs):
        self.ctx = ctx
        self._rows_vao = ctx.vertex_array(
            programs.get("fullscreen.vert", "near_surfaces.frag", defines=("ROWS",)), []
        )
        self._columns_vao = ctx.vertex_array(
            programs.get("fullscreen.vert", "near_surfaces.frag"), []
        )
        for vao, sampler in ((self._rows_vao, "u_ids"), (self._columns_vao, "u_rows")):
            apply_uniforms(vao.program, {sampler: 0, "u_reach": FXAA_REACH_PX})
        self.depth = self._rows = self._rows_fbo = self._depth_fbo = None
        self.layer_version: int | None = None  # the molecule layer the mask was made from

    def get(self, frame: Frame):
        """The mask of the frame's molecule layer (made again for a new one)."""
        ctx, size = self.ctx, frame.size
        if self.depth is None or self.depth.size != tuple(size):
            self.release()
            self._rows = ctx.texture(size, 1, dtype="f1")
            self.depth = ctx.depth_texture(size)
            self._rows_fbo = ctx.framebuffer([self._rows])
            self._depth_fbo = ctx.framebuffer([], self.depth)
        if self.layer_version != frame.plan.layer_version:
            # Nothing lies near a surface beyond the molecule's pixels grown by the reach (the
            # probe's pixels beyond them are antialiased whole: the shading's background rectangle).
            area = grow_rect(frame.molecule_rect(), FXAA_REACH_PX, size)
            ctx.disable(ctx.BLEND | ctx.DEPTH_TEST)
            frame.targets.ids.use(0)
            self._rows_fbo.use()
            self._rows_fbo.scissor = area
            self._rows_vao.render(ctx.TRIANGLES, vertices=3)
            self._rows_fbo.scissor = None
            self._depth_fbo.use()
            self._depth_fbo.clear(depth=1.0)
            if area is not None:
                self._rows.use(0)
                self._depth_fbo.scissor = area
                ctx.enable_only(ctx.DEPTH_TEST)
                ctx.depth_func = "1"  # written whatever it held
                self._columns_vao.render(ctx.TRIANGLES, vertices=3)
                ctx.depth_func = "<"
                ctx.disable(ctx.DEPTH_TEST)
                self._depth_fbo.scissor = None
            self.layer_version = frame.plan.layer_version
        return self.depth

    def release(self) -> None:
        if self.depth is not None:
            release_framebuffers(self.ctx, self._rows_fbo, self._depth_fbo)
            self._rows.release()
            self.depth.release()
            self.depth = self._rows = self._rows_fbo = self._depth_fbo = None
            self.layer_version = None


class FxaaPass(Pass):
    name = "fxaa"

    def __init__(self, ctx, programs):
        self.prog = programs.get("fullscreen.vert", "fxaa.frag")
        self.vao = ctx.vertex_array(self.prog, [])
        self.near_vao = ctx.vertex_array(
            programs.get("fullscreen.vert", "fxaa.frag", defines=("AT_FAR_PLANE",)), []
        )
        for vao in (self.vao, self.near_vao):
            if "u_color" in vao.program:
                vao.program["u_color"].value = 0
        self.near_surfaces = NearSurfaces(ctx, programs)
        # The kept picture tested against the near-surface mask
        self._depth_tested = DepthTestedTarget(ctx)

    def run(self, frame: Frame) -> None:
        ctx, t = frame.ctx, frame.targets
        if not frame.scene.effects.fxaa:
            ctx.copy_framebuffer(frame.output_fbo, t.lit_fbo)
            return
        target, whole, near = frame.output_fbo, full_rect(frame.size), None
        if frame.plan.layered:
            target = t.kept_picture("antialiased")
            whole, near = self.regions(frame.plan)
        if whole is not None or near is not None:
            t.lit.use(0)
            w, h = frame.size
            for vao in (self.vao, self.near_vao):
                apply_uniforms(vao.program, {"u_texel": (1.0 / w, 1.0 / h)})
            ctx.disable(ctx.DEPTH_TEST | ctx.BLEND)
            if whole is not None:
                target.use()
                target.viewport = (0, 0, w, h)
                target.scissor = whole
                self.vao.render(ctx.TRIANGLES, vertices=3)
                target.scissor = None
            near = subtract_rect(near, whole)  # what the whole draw did not cover
            if near:
                tested = self._depth_tested.framebuffer(
                    target.color_attachments[0], self.near_surfaces.get(frame)
                )
                t.lit.use(0)  # again: making the mask used unit 0
                tested.use()
                for rect in near:
                    tested.scissor = rect
                    self._depth_tested.draw(self.near_vao, ">")
                tested.scissor = None
        if target is not frame.output_fbo:
            ctx.copy_framebuffer(frame.output_fbo, target)

    @staticmethod
    def regions(plan) -> tuple[Rect | None, Rect | None]:
        """Where the plan has the lit picture change, grown by FXAA's reach: (what to
        antialias whole: the changed background and the cues; what to antialias near the
        surfaces only: the changed surfaces)."""
        size = plan.size
        whole = grow_rect(
            union_rect(plan.region(LIT_BACKGROUND), plan.region(OVERLAY)), FXAA_REACH_PX, size
        )
        return whole, grow_rect(plan.region(LIT), FXAA_REACH_PX, size)

    def release(self) -> None:
        self.vao.release()
        self.near_vao.release()
        self.near_surfaces.release()
        self._depth_tested.release()
