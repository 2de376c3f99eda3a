"""G-buffer pass of the atoms: ray-cast sphere impostors.

Modes: "quad" (default; a geometry shader emits one camera-facing square per sphere,
see shaders/sphere_bound.glsl) and "sprite" (a low-end option: one point sprite per
sphere; spheres vanish once their centre leaves the view and large spheres are limited
by the driver's maximum point size). Both cast the same exact ray per pixel.
"""

from __future__ import annotations

import numpy as np
from sasprobe.render.gl.buffers import SPHERE_FORMAT
from sasprobe.render.gl.uniforms import apply_planes, apply_uniforms
from sasprobe.render.passes.base import MOLECULE, Frame, Pass

MODES = ("quad", "sprite")  # this pass's; passes/mesh.py draws "mesh"
SPHERE_MODES = (*MODES, "mesh")  # what --spheres and Renderer(sphere_mode=...) take


class SpherePass(Pass):
    name = "spheres"
    layer = MOLECULE

    def __init__(self, ctx, programs, buffers, mode: str = "quad"):
        if mode not in MODES:
            raise ValueError(f"sphere mode must be one of {MODES}, got {mode!r}")
        self.mode = mode
        if mode == "quad":
            self.prog = programs.get("sphere.vert", "sphere.frag", "sphere.geom")
        else:
            self.prog = programs.get("sphere.vert", "sphere.frag", defines=("SPRITE",))
        self.vao = ctx.vertex_array(
            self.prog,
            [(buffers.spheres, SPHERE_FORMAT, "in_sphere", "in_color")],
            index_buffer=buffers.selection,
            index_element_size=4,
        )

    def state(self):
        return self.mode

    def run(self, frame: Frame) -> None:
        ctx = frame.ctx
        ids = frame.scene.sphere_selection(frame.camera)
        frame.buffers.set_selection(ids)
        if frame.buffers.n_selected == 0:
            return
        planes = [frame.planes]
        if frame.cube is not None:
            planes.append(frame.cube.planes())
        planes.append(frame.near_plane()[None, :])
        apply_uniforms(self.prog, frame.raster_camera_uniforms())
        apply_planes(self.prog, np.concatenate(planes))
        apply_uniforms(self.prog, {"u_probe": 0})
        draw_spheres(ctx, frame, self.vao, frame.buffers.n_selected, sprite=self.mode == "sprite")

    def release(self) -> None:
        self.vao.release()


def draw_spheres(ctx, frame: Frame, vao, count: int, sprite: bool) -> None:
    """Draw `count` sphere points into the G-buffer with depth test and depth clamping
    (so a sphere crossing the near plane is capped there rather than cut open)."""
    frame.targets.gbuffer_fbo.use()
    flags = ctx.DEPTH_TEST | (ctx.PROGRAM_POINT_SIZE if sprite else 0)
    ctx.enable_only(flags)
    ctx.depth_func = "<"
    ctx.depth_clamp_range = (0.0, 1.0)
    try:
        vao.render(ctx.POINTS, vertices=count)
    finally:
        ctx.depth_clamp_range = None
