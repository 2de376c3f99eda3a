"""A second G-buffer that holds one rectangle of the first: what the molecule layer has
under the probe, saved before the probe is drawn and put back before the next frame
draws it elsewhere (the frame planner, render/frame_planner.py). Copies are a fragment pass
that writes the four layers and the depth (gl_FragDepth, depth test "always") inside a
scissor box, so they cost what the rectangle holds, not the frame."""

from __future__ import annotations

from sasprobe.render.gl.programs import ProgramCache
from sasprobe.render.gl.targets import RenderTargets
from sasprobe.render.gl.textures import release_framebuffers

LAYERS = ("albedo", "position", "normal", "ids", "depth")


class GBufferStash:
    def __init__(self, ctx, programs: ProgramCache, size: tuple[int, int]):
        self.ctx = ctx
        self.size = tuple(size)
        self.albedo = ctx.texture(self.size, 4, dtype="f1")
        self.position = ctx.texture(self.size, 4, dtype="f4")
        self.normal = ctx.texture(self.size, 4, dtype="f4")
        self.ids = ctx.texture(self.size, 2, dtype="i4")
        self.depth = ctx.depth_texture(self.size)
        for tex in (self.albedo, self.position, self.normal, self.ids):
            tex.filter = (ctx.NEAREST, ctx.NEAREST)
        self.fbo = ctx.framebuffer([self.albedo, self.position, self.normal, self.ids], self.depth)
        self.prog = programs.get("fullscreen.vert", "gbuffer_copy.frag")
        self.vao = ctx.vertex_array(self.prog, [])
        for unit, name in enumerate(LAYERS):
            self.prog[f"u_src_{name}"].value = unit

    def save(self, targets: RenderTargets, rect) -> None:
        """The rectangle of the renderer's G-buffer into the stash."""
        self._copy([getattr(targets, n) for n in LAYERS], self.fbo, rect)

    def restore(self, targets: RenderTargets, rect) -> None:
        """The stashed rectangle back into the renderer's G-buffer."""
        self._copy([getattr(self, n) for n in LAYERS], targets.gbuffer_fbo, rect)

    def _copy(self, sources, fbo, rect) -> None:
        if rect is None:
            return
        ctx = self.ctx
        for unit, tex in enumerate(sources):
            if tex is sources[-1]:
                tex.compare_func = ""  # sampled as a value, not compared
            tex.use(unit)
        fbo.use()
        fbo.scissor = tuple(int(v) for v in rect)
        ctx.enable_only(ctx.DEPTH_TEST)
        ctx.depth_func = "1"  # always: the copy overwrites the depth
        try:
            self.vao.render(ctx.TRIANGLES, vertices=3)
        finally:
            fbo.scissor = None
            ctx.depth_func = "<"

    def release(self) -> None:
        release_framebuffers(self.ctx, self.fbo)
        for obj in (self.vao, self.albedo, self.position, self.normal, self.ids, self.depth):
            obj.release()
