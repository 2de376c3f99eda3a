"""Final overlay pass: the session's marks as numbered badges over the image.

Each mark (the scene's `marks`, dropped at the probe's position) is a round badge with
its number, a fixed BADGE_PX wide at its projection, drawn over everything so a mark is
never lost, and faded where atoms hide it (shaders/marks.vert). The badges are drawn
with Pillow into one atlas texture, redrawn only when the marks change.
"""

from __future__ import annotations

import math

import numpy as np
from sasprobe.molecule.colors import MARK_COLOR
from sasprobe.render.gl.uniforms import apply_uniforms
from sasprobe.render.passes.base import Frame, Pass

BADGE_PX = 22
BADGE_COLOR = (*(round(c * 255) for c in MARK_COLOR), 255)
COLUMNS = 32  # badges per atlas row


def badge_atlas(numbers: list[int]) -> np.ndarray:
    """RGBA uint8 atlas, row 0 = top: badge k (white number on a violet disc) in cell k."""
    from PIL import Image, ImageDraw, ImageFont

    rows = max(math.ceil(len(numbers) / COLUMNS), 1)
    img = Image.new("RGBA", (COLUMNS * BADGE_PX, rows * BADGE_PX), (0, 0, 0, 0))
    draw = ImageDraw.Draw(img)
    font = ImageFont.load_default()
    for k, number in enumerate(numbers):
        x, y = (k % COLUMNS) * BADGE_PX, (k // COLUMNS) * BADGE_PX
        draw.ellipse(
            (x + 1, y + 1, x + BADGE_PX - 2, y + BADGE_PX - 2),
            fill=BADGE_COLOR,
            outline=(255, 255, 255, 255),
        )
        text = str(number)
        box = draw.textbbox((0, 0), text, font=font)
        draw.text(
            (
                x + (BADGE_PX - (box[2] - box[0])) / 2 - box[0],
                y + (BADGE_PX - (box[3] - box[1])) / 2 - box[1],
            ),
            text,
            fill=(255, 255, 255, 255),
            font=font,
        )
    return np.asarray(img)


class MarksPass(Pass):
    name = "marks"

    def __init__(self, ctx, programs):
        self.ctx = ctx
        self.prog = programs.get("marks.vert", "marks.frag")
        self.instances = ctx.buffer(reserve=16)
        self.vao = ctx.vertex_array(self.prog, [(self.instances, "4f /i", "in_mark")])
        self.atlas = None
        self._shown: tuple | None = None

    def enabled(self, frame: Frame) -> bool:
        return bool(frame.scene.marks) and frame.scene.effects.marks

    def _upload(self, marks) -> None:
        key = tuple((m.id, *m.position) for m in marks)
        if key == self._shown:
            return
        image = badge_atlas([m.id for m in marks])
        if self.atlas is not None:
            self.atlas.release()
        self.atlas = self.ctx.texture((image.shape[1], image.shape[0]), 4, image.tobytes())
        self.atlas.filter = (self.ctx.NEAREST, self.ctx.NEAREST)
        records = np.array([[*m.position, k] for k, m in enumerate(marks)], dtype=np.float32)
        self.instances.orphan(records.nbytes)
        self.instances.write(records.tobytes())
        self._shown = key

    def run(self, frame: Frame) -> None:
        ctx, marks = frame.ctx, frame.scene.marks
        self._upload(marks)
        w, h = frame.size
        self.atlas.use(0)
        frame.targets.position.use(1)
        camera = frame.raster_camera_uniforms()
        apply_uniforms(
            self.prog,
            {
                "u_viewproj": camera["u_viewproj"],
                "u_eye": camera["u_eye"],
                "u_screen": (float(w), float(h)),
                "u_badge_px": float(BADGE_PX),
                "u_cells": (float(COLUMNS), float(max(math.ceil(len(marks) / COLUMNS), 1))),
                "u_tolerance": float(frame.scene.probe_radius) + 0.5,
                "u_atlas": 0,
                "u_position": 1,
            },
        )
        frame.output_fbo.use()
        frame.output_fbo.viewport = (0, 0, w, h)
        ctx.enable_only(ctx.BLEND)
        ctx.blend_func = ctx.SRC_ALPHA, ctx.ONE_MINUS_SRC_ALPHA
        self.vao.render(ctx.TRIANGLE_STRIP, vertices=4, instances=len(marks))
        ctx.disable(ctx.BLEND)

    def release(self) -> None:
        self.vao.release()
        self.instances.release()
        if self.atlas is not None:
            self.atlas.release()
