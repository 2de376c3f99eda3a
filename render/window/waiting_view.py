"""What a window shows while a daemon's structure is on its way: the navigation cube's wire
and the probe where the daemon's poses put them, in the workspace view, with the readout's
progress line over them. The poses come well before the structure (a large one is fetched
and prepared on other threads), so the window shows the arm at work at once instead of an
empty picture. Drawn straight into the window: no G-buffer, no structure."""

from __future__ import annotations

import numpy as np
from sasprobe.render.gl.uniforms import apply_uniforms
from sasprobe.render.passes.backbone import cube_uniforms
from sasprobe.render.passes.base import raster_camera_uniforms
from sasprobe.render.passes.navcube import WIRE_COLOR, WIRE_WIDTH_PX, cube_edges
from sasprobe.render.passes.probe import PROBE_COLOR
from sasprobe.render.passes.probe_cues import CIRCLE_SEGMENTS, silhouette
from sasprobe.render.workspace_view import workspace_camera


class WaitingView:
    def __init__(self, ctx, programs):
        self.ctx = ctx
        self.wire = programs.get("cube.vert", "cube.frag", "wide_line.geom")
        self.wire_vbo = ctx.buffer(cube_edges().tobytes())
        self.wire_vao = ctx.vertex_array(self.wire, [(self.wire_vbo, "3f", "in_position")])
        self.disc = programs.get("screen.vert", "solid.frag")
        self.disc_vbo = ctx.buffer(reserve=CIRCLE_SEGMENTS * 3 * 8)
        self.disc_vao = ctx.vertex_array(self.disc, [(self.disc_vbo, "2f", "in_ndc")])

    def draw(self, fbo, size: tuple[int, int], cube, probe, background) -> None:
        """Clear `fbo` to `background` and draw `cube` (a NavCube) and `probe` (a Probe, or None)
        as the workspace view frames the cube."""
        ctx = self.ctx
        fbo.use()
        fbo.viewport = (0, 0, *size)
        fbo.clear(*background, 1.0)
        camera = workspace_camera(cube, size[0] / size[1])
        reach = cube.half * np.sqrt(3.0)
        camera.fit_clip_range(
            cube.center,
            reach
            if probe is None
            else max(reach, float(np.linalg.norm(probe.center - cube.center)) + probe.radius),
        )
        proj = camera.projection(size[0] / size[1])
        viewproj = proj @ camera.view()
        ctx.enable_only(0)
        if probe is not None:
            ring = silhouette(probe.center, probe.radius, camera.eye)[::2]
            if ring.size:
                clip = np.column_stack([ring, np.ones(len(ring))]) @ viewproj.T
                if np.all(clip[:, 3] > 0):
                    ndc = clip[:, :2] / clip[:, 3:4]
                    middle = ndc.mean(axis=0)
                    fan = np.stack(
                        [np.broadcast_to(middle, ndc.shape), ndc, np.roll(ndc, -1, axis=0)], axis=1
                    )
                    self.disc_vbo.write(fan.astype(np.float32).tobytes())
                    apply_uniforms(self.disc, {"u_color": (*PROBE_COLOR, 1.0)})
                    self.disc_vao.render(ctx.TRIANGLES, vertices=3 * len(ndc))
        apply_uniforms(
            self.wire,
            {
                **raster_camera_uniforms(camera, viewproj, proj, size),
                **cube_uniforms(cube),
                "u_radius": 0.0,
                "u_min_width_px": WIRE_WIDTH_PX,
                "u_proj_scale": float(proj[1, 1]) * size[1] * 0.5,
                "u_wire_color": WIRE_COLOR,
            },
        )
        self.wire_vao.render(ctx.LINES, vertices=24)

    def release(self) -> None:
        for obj in (self.wire_vao, self.wire_vbo, self.disc_vao, self.disc_vbo):
            obj.release()
