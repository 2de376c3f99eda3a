"""Compute programs over an image: the dispatch every lighting program uses, and a shader
compiled per case."""

from __future__ import annotations

from sasprobe.render.gl.programs import source
from sasprobe.render.gl.uniforms import apply_uniforms

LOCAL_SIZE = 8  # compute work-group edge of the 2D programs (the shaders' local_size_x/y)


def dispatch(program, width: int, height: int) -> None:
    """Run a 2D compute program over width × height, then make its writes visible to whatever
    reads them next (texture fetch, image load, buffer read-back)."""
    program.run(
        group_x=(width + LOCAL_SIZE - 1) // LOCAL_SIZE,
        group_y=(height + LOCAL_SIZE - 1) // LOCAL_SIZE,
    )
    program.ctx.memory_barrier()


class ComputeProgram:
    """A compute program over an image, with an uploaded grid bound when it has one (the base
    of the lighting's programs; the grid is anything with bind() and uniforms())."""

    def __init__(self, ctx, shader: str, gpu_grid=None, defines: tuple[str, ...] = ()):
        self.ctx = ctx
        self.grid = gpu_grid
        self.program = ctx.compute_shader(source(shader, defines))

    def run(self, width: int, height: int, uniforms: dict) -> None:
        if self.grid is not None:
            self.grid.bind()
            uniforms = {**self.grid.uniforms(), **uniforms}
        apply_uniforms(self.program, uniforms)
        dispatch(self.program, width, height)

    def release(self) -> None:
        self.program.release()


class ComputeVariants:
    """One compute shader compiled per set of #defines, each on first use. llvmpipe runs
    every instruction of a program for each group of lanes whichever way its branches go,
    uniform ones included, so each case gets a program holding only its own code."""

    def __init__(self, ctx, shader: str, gpu_grid=None):
        self.ctx = ctx
        self.shader = shader
        self.grid = gpu_grid
        self._programs: dict[tuple[str, ...], ComputeProgram] = {}

    def get(self, *cases: tuple[str, bool]) -> ComputeProgram:
        """The program with the defines whose case holds, e.g. get(("LIGHT_BUFFER", True))."""
        defines = tuple(name for name, on in cases if on)
        if defines not in self._programs:
            self._programs[defines] = ComputeProgram(self.ctx, self.shader, self.grid, defines)
        return self._programs[defines]

    def release(self) -> None:
        for compute in self._programs.values():
            compute.release()
        self._programs.clear()
