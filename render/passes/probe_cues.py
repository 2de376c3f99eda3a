"""Forward pass: what the hand feels, drawn over the lit image, and the probe always findable.

- an outline of the probe wherever something in front hides it (drawn where the G-buffer
  is nearer than the probe's rim and is not the probe itself);
- the device tip as a ghost sphere (its outline, seen through everything) with a spring
  to the probe, whenever the two differ (in contact the tip is inside the surface and
  the probe on it);
- the force on the hand as an arrow from the probe, its length proportional to the
  force (ARROW_RADII probe radii at the device's continuous rating), green below half
  the continuous rating, yellow up to it and red above it;
- an arrow at the edge of the picture pointing at the probe when it is off screen.

Lines go through shaders/wide_line.geom (as the trace and the cube wire do); the
outlines are the silhouette circles of the spheres as the camera sees them.
"""

from __future__ import annotations

import math

import numpy as np
from sasprobe.molecule.colors import force_color
from sasprobe.protocol.view import ARROW_RADII
from sasprobe.render.frame_planner import OVERLAY
from sasprobe.render.gl.uniforms import apply_uniforms
from sasprobe.render.passes.backbone import line_width_uniforms
from sasprobe.render.passes.base import Frame, Pass
from sasprobe.render.rects import ndc_rect, points_rect, union_rect

OUTLINE_COLOR = (1.0, 0.85, 0.3)
GHOST_COLOR = (0.55, 0.8, 1.0)
LINE_WIDTH_PX = 2.0
DRAWN_MARGIN_PX = 3  # around the lines' points: half the line width and a pixel of rounding
CIRCLE_SEGMENTS = 48
GHOST_MIN_RADII = 0.05  # the ghost shows when tip and probe are further apart than this many radii
EDGE_ARROW_NDC = 0.06  # size of the off-screen arrow
EDGE_INSET_NDC = 0.04
MAX_VERTICES = 2 * (3 * CIRCLE_SEGMENTS + 40)


def silhouette(center, radius: float, eye, segments: int = CIRCLE_SEGMENTS) -> np.ndarray:
    """Line-list endpoints (2·segments, 3) of a sphere's silhouette circle seen from `eye`
    (the circle where the eye's tangent cone touches it)."""
    c, e = np.asarray(center, dtype=np.float64), np.asarray(eye, dtype=np.float64)
    to_eye = e - c
    d = float(np.linalg.norm(to_eye))
    if d <= radius:
        return np.zeros((0, 3))
    w = to_eye / d
    u = np.cross(w, [0.0, 0.0, 1.0] if abs(w[2]) < 0.9 else [1.0, 0.0, 0.0])
    u /= np.linalg.norm(u)
    v = np.cross(w, u)
    rho = radius * math.sqrt(d * d - radius * radius) / d
    middle = c + w * (radius * radius / d)
    a = np.linspace(0.0, 2.0 * math.pi, segments + 1)
    ring = middle + rho * (np.cos(a)[:, None] * u + np.sin(a)[:, None] * v)
    return np.repeat(ring, 2, axis=0)[1:-1]


def spring(a, b, across, coils: int = 6) -> np.ndarray:
    """Line-list endpoints of a zig-zag spring from a to b, `across` (a vector) wide."""
    a, b = np.asarray(a, dtype=np.float64), np.asarray(b, dtype=np.float64)
    steps = 2 * coils
    points = [
        a + (b - a) * k / steps + (across if k % 2 else -across) * (0 < k < steps)
        for k in range(steps + 1)
    ]
    return np.repeat(np.array(points), 2, axis=0)[1:-1]


def edge_arrow(ndc: np.ndarray) -> np.ndarray | None:
    """A triangle (3, 2) at the picture's edge pointing toward an off-screen point (NDC x, y
    and the sign of its clip w: behind the eye the direction is flipped), or None on screen."""
    x, y, w = float(ndc[0]), float(ndc[1]), float(ndc[2])
    if w > 0 and abs(x) <= 1.0 and abs(y) <= 1.0:
        return None
    direction = np.array([x, y]) * (1.0 if w > 0 else -1.0)
    n = float(np.linalg.norm(direction))
    direction = direction / n if n > 0 else np.array([0.0, -1.0])
    reach = 1.0 - EDGE_INSET_NDC
    tip = direction * reach / max(abs(direction[0]), abs(direction[1]))
    side = np.array([-direction[1], direction[0]])
    base = tip - direction * EDGE_ARROW_NDC * 2.0
    return np.array([tip, base + side * EDGE_ARROW_NDC, base - side * EDGE_ARROW_NDC])


class ProbeCuesPass(Pass):
    name = "probe_cues"

    def __init__(self, ctx, programs):
        self.ctx = ctx
        self.lines = programs.get("backbone.vert", "cue.frag", "wide_line.geom")
        self.screen = programs.get("screen.vert", "solid.frag")
        self.vbo = ctx.buffer(reserve=MAX_VERTICES * 28)
        # the trace's vertex layout; the cue shader reads no atom id, so that field is skipped
        self.vao = ctx.vertex_array(self.lines, [(self.vbo, "3f 3f 4x", "in_position", "in_color")])
        self.tri = ctx.buffer(reserve=3 * 8)
        self.tri_vao = ctx.vertex_array(self.screen, [(self.tri, "2f", "in_ndc")])

    def enabled(self, frame: Frame) -> bool:
        return frame.scene.probe is not None and frame.scene.effects.probe

    def footprint(self, frame: Frame) -> dict:
        """What the cues cover (drawn over the lit picture)."""
        outline, lines, arrow = self._shapes(frame)
        drawn = None
        for points, _, _ in [outline, *lines]:
            if points.size:
                drawn = union_rect(
                    drawn,
                    points_rect(points[:MAX_VERTICES], frame.viewproj, frame.size, DRAWN_MARGIN_PX),
                )
        if arrow is not None:
            drawn = union_rect(drawn, ndc_rect(arrow, frame.size, DRAWN_MARGIN_PX))
        return {OVERLAY: drawn}

    def _shapes(self, frame: Frame):
        """(the probe's outline, the other line lists, the off-screen arrow or None), lines
        as (points, colour, alpha): found once a frame."""
        key = "probe cues"
        if key not in frame._found:
            scene, probe, eye = frame.scene, frame.scene.probe, frame.camera.eye
            outline = (silhouette(probe.center, probe.radius, eye), OUTLINE_COLOR, 1.0)
            lines = []
            if (
                probe.goal is not None
                and np.linalg.norm(probe.goal - probe.center) > GHOST_MIN_RADII * probe.radius
            ):
                across = np.cross(probe.goal - probe.center, eye - probe.center)
                norm = float(np.linalg.norm(across))
                across = across / norm * 0.25 * probe.radius if norm > 0 else np.zeros(3)
                lines.append(
                    (
                        np.concatenate(
                            [
                                silhouette(probe.goal, probe.radius, eye),
                                spring(probe.center, probe.goal, across),
                            ]
                        ),
                        GHOST_COLOR,
                        0.8,
                    )
                )
            if probe.force_n is not None and scene.force_ratings_n is not None:
                arrow = force_arrow(probe, eye, *scene.force_ratings_n)
                if arrow is not None:
                    lines.append(arrow)
            clip = frame.viewproj @ np.array([*probe.center, 1.0])
            w = float(clip[3])
            ndc = np.array([clip[0] / w, clip[1] / w, w]) if w != 0 else np.array([0.0, -2.0, 1.0])
            frame._found[key] = (outline, lines, edge_arrow(ndc))
        return frame._found[key]

    def run(self, frame: Frame) -> None:
        ctx = frame.ctx
        outline, lines, arrow = self._shapes(frame)
        frame.targets.lit_fbo.use()
        ctx.enable_only(ctx.DEPTH_TEST | ctx.BLEND)
        ctx.blend_func = ctx.SRC_ALPHA, ctx.ONE_MINUS_SRC_ALPHA
        apply_uniforms(self.lines, frame.raster_camera_uniforms())
        apply_uniforms(self.lines, line_width_uniforms(frame, 0.0, LINE_WIDTH_PX))
        frame.targets.ids.use(0)
        apply_uniforms(self.lines, {"u_ids": 0, "u_hidden_only": 1})
        ctx.depth_func = ">"  # only where something nearer than the probe's rim covers it
        self._draw(*outline)
        apply_uniforms(self.lines, {"u_hidden_only": 0})
        # The rest shows through: the tip is inside the surface in contact
        ctx.disable(ctx.DEPTH_TEST)
        for line in lines:
            self._draw(*line)
        if arrow is not None:
            self.tri.write(arrow.astype(np.float32).tobytes())
            apply_uniforms(self.screen, {"u_color": (*OUTLINE_COLOR, 1.0)})
            self.tri_vao.render(self.ctx.TRIANGLES, vertices=3)
        ctx.disable(ctx.BLEND)

    def _draw(self, points: np.ndarray, color, alpha: float) -> None:
        if points.size == 0:
            return
        points = points[:MAX_VERTICES]
        records = np.zeros(points.shape[0], dtype=[("p", "3f4"), ("c", "3f4"), ("id", "i4")])
        records["p"] = points
        records["c"] = color
        records["id"] = -1
        self.vbo.write(records.tobytes())
        apply_uniforms(self.lines, {"u_alpha": float(alpha)})
        self.vao.render(self.ctx.LINES, vertices=points.shape[0])

    def release(self) -> None:
        for obj in (self.vao, self.vbo, self.tri_vao, self.tri):
            obj.release()


def force_arrow(probe, eye, continuous: float, peak: float):
    """The force arrow's line list, colour and alpha; None without a force."""
    force = float(np.linalg.norm(probe.force_n))
    if force <= 1e-6 or continuous <= 0:
        return None
    direction = probe.force_n / force
    start = probe.center + direction * probe.radius
    end = start + direction * ARROW_RADII * probe.radius * min(force, peak) / continuous
    side = np.cross(direction, eye - end)
    n = float(np.linalg.norm(side))
    head = 0.3 * np.linalg.norm(end - start)
    side = side / n * head * 0.5 if n > 0 else np.zeros(3)
    back = end - direction * head
    return (
        np.array([start, end, end, back + side, end, back - side]),
        force_color(force, continuous),
        1.0,
    )
