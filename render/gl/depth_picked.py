"""Full-screen passes over the pixels a depth test against the G-buffer picks.

llvmpipe runs every instruction of a shader for each block of pixels, whichever way its
branches go, and skips only the blocks a depth test rejects before the fragment shader
runs. So a pass whose work lies on the molecule's surfaces draws one triangle at the far
plane (shaders/fullscreen.vert AT_FAR_PLANE), where the G-buffer was cleared: depth func
"==" picks the background, ">" the surfaces; the depth is tested, never written.
"""

from __future__ import annotations

from sasprobe.render.gl.programs import program
from sasprobe.render.gl.uniforms import apply_uniforms


class DepthTestedTarget:
    """A framebuffer that draws into a colour texture while testing against a depth texture
    it does not write (drawn with fullscreen.vert AT_FAR_PLANE: depth func "==" picks the
    background, ">" the surfaces), made again when either texture changes."""

    def __init__(self, ctx):
        self.ctx = ctx
        self.key: tuple | None = None
        self.fbo = None

    def framebuffer(self, colour, depth):
        """`colour` None: no colour attachment (a shader that writes images)."""
        key = (None if colour is None else colour.glo, depth.glo)
        if key != self.key:
            self.release()
            self.fbo = self.ctx.framebuffer([] if colour is None else [colour], depth)
            self.fbo.depth_mask = False
            self.key = key
        return self.fbo

    def draw(self, vao, depth_func: str) -> None:
        """One full-screen triangle at the far plane through the depth test, into the bound
        framebuffer (its scissor box as set)."""
        ctx = self.ctx
        ctx.enable_only(ctx.DEPTH_TEST)
        ctx.depth_func = depth_func
        try:
            vao.render(ctx.TRIANGLES, vertices=3)
        finally:
            ctx.depth_func = "<"

    def release(self) -> None:
        if self.fbo is not None:
            if self.ctx.fbo is self.fbo:  # not the bound one (see RenderTargets.release)
                self.ctx.detect_framebuffer(0).use()
            self.fbo.release()
            self.fbo = self.key = None



class DepthPickedPass:
    """A fragment shader drawn as above, compiled per set of #defines (as ComputeVariants
    compiles a compute shader), with a GPU grid bound when it has one."""

    def __init__(self, ctx, fragment: str, gpu_grid=None):
        self.ctx = ctx
        self.fragment = fragment
        self.grid = gpu_grid
        self.target = DepthTestedTarget(ctx)
        self._vaos: dict[tuple[str, ...], object] = {}

    def _vao(self, cases):
        defines = ("AT_FAR_PLANE",) + tuple(name for name, on in cases if on)
        if defines not in self._vaos:
            self._vaos[defines] = self.ctx.vertex_array(
                program(self.ctx, "fullscreen.vert", self.fragment, defines=defines), [])
        return self._vaos[defines]

    def run(self, colour, depth, rect, picks, uniforms: dict, clear: float | None = None) -> None:
        """Into `colour` over `rect` (x, y, w, h): cleared to `clear` if given, then each of
        `picks`, (cases, depth func), drawn in turn. With `colour` None the shader writes
        images (its depth test declared early, or rejected pixels would write too), made
        visible to what reads them next."""
        if self.grid is not None:
            self.grid.bind()
            uniforms = {**self.grid.uniforms(), **uniforms}
        fbo = self.target.framebuffer(colour, depth)
        fbo.use()
        box = tuple(int(v) for v in rect)
        fbo.scissor = box
        if clear is not None:
            fbo.clear(clear, clear, clear, clear, viewport=box)
        for cases, depth_func in picks:
            vao = self._vao(cases)
            apply_uniforms(vao.program, uniforms)
            self.target.draw(vao, depth_func)
        fbo.scissor = None
        if colour is None:
            self.ctx.memory_barrier()

    def release(self) -> None:
        for vao in self._vaos.values():
            vao.program.release()
            vao.release()
        self._vaos.clear()
        self.target.release()
