"""Full-screen fragment shaders drawn over the pixels a depth test against the G-buffer
picks, and the framebuffers they draw into.

llvmpipe runs every instruction of a shader for each block of pixels, whichever way its
branches go, and skips only the blocks a depth test rejects before the fragment shader
runs. So a draw whose work lies on the molecule's surfaces is one triangle at the far plane
(shaders/fullscreen.vert AT_FAR_PLANE), where the G-buffer was cleared: depth func "=="
picks the background, ">" the surfaces; the depth is tested, never written. llvmpipe also
runs a fragment shader faster than the same compute shader, so a draw may pick every pixel
(depth func "1").
"""

from __future__ import annotations

from sasprobe.render.gl.programs import program
from sasprobe.render.gl.textures import release_framebuffers
from sasprobe.render.gl.uniforms import apply_uniforms


class DepthTestedTarget:
    """Framebuffers that draw into a colour texture while testing against a depth texture
    they do not write (drawn with fullscreen.vert AT_FAR_PLANE: depth func "==" picks the
    background, ">" the surfaces). The last MAX_KEPT pairs are kept: a program draws into a few
    targets (the shadows: the sun's and the probe light's, whole frames and layered ones;
    the shading: the lit picture or the kept one). Pairs are told apart by the texture objects
    themselves, which are held, so a texture made after another's release (and given its
    GL name) is never taken for it."""

    MAX_KEPT = 4

    def __init__(self, ctx):
        self.ctx = ctx
        self._kept: list[tuple[object, object, object]] = []  # (colour, depth, fbo), newest last

    def framebuffer(self, colour, depth):
        """`colour` None: no colour attachment (a shader that writes images)."""
        for entry in self._kept:
            if entry[0] is colour and entry[1] is depth:
                return entry[2]
        fbo = self.ctx.framebuffer([] if colour is None else [colour], depth)
        fbo.depth_mask = False
        self._kept.append((colour, depth, fbo))
        if len(self._kept) > self.MAX_KEPT:
            release_framebuffers(self.ctx, self._kept.pop(0)[2])
        return fbo

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
        release_framebuffers(self.ctx, *(fbo for _, _, fbo in self._kept))
        self._kept.clear()


class DepthPickedDraw:
    """A fragment shader drawn over the pixels a depth test picks, compiled per set of
    #defines (as ComputeVariants compiles a compute shader), with an uploaded grid bound when
    it has one."""

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
                program(self.ctx, "fullscreen.vert", self.fragment, defines=defines), []
            )
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
