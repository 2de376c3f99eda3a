"""G-buffer pass of the atoms, in one of three modes (`--spheres`):

- "quad" (default): ray-cast impostors, one camera-facing square per sphere from a geometry
  shader (shaders/sphere_bound.glsl);
- "sprite": the same ray per pixel from one point sprite per sphere, a low-end option
  (spheres vanish once their centre leaves the view, and the driver's maximum point size
  limits large ones);
- "mesh": instanced triangle-mesh spheres (a UV sphere of 648 triangles), the baseline the
  benchmarks measure the impostors against.
"""

from __future__ import annotations

import math

import numpy as np
from sasprobe.render.gl.buffers import SPHERE_FORMAT
from sasprobe.render.gl.uniforms import apply_planes, apply_uniforms
from sasprobe.render.passes.base import Frame, Layer, Pass

MODES = ("quad", "sprite")  # SpherePass's; MeshSpherePass draws "mesh"
SPHERE_MODES = (*MODES, "mesh")  # what --spheres and Renderer(sphere_mode=...) take


def sphere_pass(ctx, programs, buffers, mode: str) -> Pass:
    """The atoms' pass of a mode of SPHERE_MODES."""
    if mode == "mesh":
        return MeshSpherePass(ctx, programs, buffers)
    return SpherePass(ctx, programs, buffers, mode)


class SpherePass(Pass):
    name = "spheres"
    layer = Layer.MOLECULE

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


def uv_sphere(slices: int = 18, stacks: int = 19) -> tuple[np.ndarray, np.ndarray]:
    """Unit sphere: (vertices (V, 3) float32, triangle indices (T, 3) uint32),
    2 * slices * (stacks - 1) triangles."""
    verts = [(0.0, 1.0, 0.0)]
    for i in range(1, stacks):
        theta = math.pi * i / stacks
        for j in range(slices):
            phi = 2.0 * math.pi * j / slices
            verts.append(
                (math.sin(theta) * math.cos(phi), math.cos(theta), math.sin(theta) * math.sin(phi))
            )
    verts.append((0.0, -1.0, 0.0))
    bottom = len(verts) - 1
    tris = []

    def ring(i, j):  # vertex index of ring i (1 .. stacks - 1), slice j
        return 1 + (i - 1) * slices + (j % slices)

    for j in range(slices):
        tris.append((0, ring(1, j + 1), ring(1, j)))
        tris.append((bottom, ring(stacks - 1, j), ring(stacks - 1, j + 1)))
    for i in range(1, stacks - 1):
        for j in range(slices):
            a, b, c, d = ring(i, j), ring(i, j + 1), ring(i + 1, j), ring(i + 1, j + 1)
            tris += [(a, b, c), (b, d, c)]
    return np.array(verts, dtype=np.float32), np.array(tris, dtype=np.uint32)


class MeshSpherePass(Pass):
    name = "mesh_spheres"
    mode = "mesh"
    layer = Layer.MOLECULE

    def __init__(self, ctx, programs, buffers, slices: int = 18, stacks: int = 19):
        verts, tris = uv_sphere(slices, stacks)
        self.n_triangles = len(tris)
        self.prog = programs.get("mesh.vert", "mesh.frag")
        self.vertex_buffer = ctx.buffer(verts.tobytes())
        self.index_buffer = ctx.buffer(tris.tobytes())
        n = max(buffers.n_atoms, 1)
        self.instances = ctx.buffer(reserve=n * 36)  # 8 floats + atom id per drawn atom
        self.records = buffers.records
        self.n_instances = 0
        self._last = None
        self.vao = ctx.vertex_array(
            self.prog,
            [
                (self.vertex_buffer, "3f", "in_vertex"),
                (self.instances, "4f 4f 1i/i", "in_sphere", "in_color", "in_atom"),
            ],
            index_buffer=self.index_buffer,
            index_element_size=4,
        )

    def state(self):
        return (self.mode, self.n_triangles)

    def run(self, frame: Frame) -> None:
        ctx = frame.ctx
        ids = frame.scene.sphere_selection(frame.camera)
        if ids is not self._last:
            inst = np.zeros(len(ids), dtype=[("rec", "<f4", 8), ("atom", "<i4")])
            inst["rec"] = self.records[ids]
            inst["atom"] = ids
            if len(ids):
                self.instances.write(inst.tobytes())
            self.n_instances, self._last = len(ids), ids
        if not self.n_instances:
            return
        apply_uniforms(self.prog, frame.raster_camera_uniforms())
        frame.targets.gbuffer_fbo.use()
        ctx.enable_only(ctx.DEPTH_TEST)
        ctx.depth_func = "<"
        self.vao.render(ctx.TRIANGLES, instances=self.n_instances)

    def release(self) -> None:
        for obj in (self.vao, self.vertex_buffer, self.index_buffer, self.instances):
            obj.release()
