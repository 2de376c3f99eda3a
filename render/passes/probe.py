"""G-buffer pass of the probe sphere (never clipped; atom id -2, kind PROBE), drawn over
the molecule layer (whose pixels under the probe the frame planner stashes first, so the
next frame can put them back: render/frame_planner.py)."""

from __future__ import annotations

from sasprobe.molecule.colors import PROBE_COLOR
from sasprobe.render.gl.buffers import SPHERE_FORMAT
from sasprobe.render.gl.uniforms import apply_planes, apply_uniforms
from sasprobe.render.passes.base import Frame, Pass
from sasprobe.render.passes.spheres import draw_spheres


class ProbePass(Pass):
    name = "probe"

    def __init__(self, ctx, programs, buffers):
        self.prog = programs.get("sphere.vert", "sphere.frag", "sphere.geom")
        self.vao = ctx.vertex_array(
            self.prog, [(buffers.probe, SPHERE_FORMAT, "in_sphere", "in_color")]
        )

    def enabled(self, frame: Frame) -> bool:
        return frame.scene.probe is not None and frame.scene.effects.probe

    def run(self, frame: Frame) -> None:
        probe = frame.scene.probe
        frame.buffers.set_probe(probe.center, probe.radius, PROBE_COLOR)
        apply_uniforms(self.prog, frame.raster_camera_uniforms())
        apply_planes(self.prog, frame.near_plane()[None, :])
        apply_uniforms(self.prog, {"u_probe": 1})
        draw_spheres(frame.ctx, frame, self.vao, 1, sprite=False)

    def release(self) -> None:
        self.vao.release()
