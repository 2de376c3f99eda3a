"""The last pass: the colour bar of a scheme that maps a number to colour (bfactor, sas;
molecule/colors.py), in the image's bottom-right corner, so a saved picture carries its scale."""

from __future__ import annotations

import numpy as np
from sasprobe.molecule.colors import ColorBar, color_bar, ramp
from sasprobe.render.gl.image_quad import ImageQuad
from sasprobe.render.passes.base import Frame, Pass
from sasprobe.render.text import PADDING, fit_text, text_font

BAR_SIZE = (180, 12)  # pixels
MARGIN = 10


def legend_image(bar: ColorBar) -> np.ndarray:
    """RGBA uint8: the title, the ramp from low (left) to high, and the end values."""
    from PIL import Image, ImageDraw

    font = text_font()[0]
    w, h = BAR_SIZE
    line = 14
    img = Image.new("RGBA", (w + 2 * PADDING, h + 2 * line + 2 * PADDING), (0, 0, 0, 150))
    draw = ImageDraw.Draw(img)
    draw.text((PADDING, PADDING), fit_text(bar.title), fill=(255, 255, 255, 255), font=font)
    colours = (ramp(np.linspace(bar.low, bar.high, w), bar.low, bar.high, bar.stops) * 255).astype(
        np.uint8
    )
    strip = Image.fromarray(np.repeat(colours[None, :, :], h, axis=0), "RGB")
    img.paste(strip, (PADDING, PADDING + line))
    low, high = f"{bar.low:.3g}", f"{bar.high:.3g}"
    draw.text((PADDING, PADDING + line + h + 1), low, fill=(255, 255, 255, 255), font=font)
    right = draw.textbbox((0, 0), high, font=font)[2]
    draw.text(
        (PADDING + w - right, PADDING + line + h + 1), high, fill=(255, 255, 255, 255), font=font
    )
    return np.asarray(img)


class LegendPass(Pass):
    name = "legend"

    def __init__(self, ctx, programs):
        self.quad = ImageQuad(ctx, programs)
        self._bar: tuple = (None, None, None)  # (structure, scheme, its ColorBar)

    def _bar_of(self, frame: Frame) -> ColorBar | None:
        structure, scheme = frame.scene.structure, frame.scene.color_scheme()
        if self._bar[0] is not structure or self._bar[1] != scheme:
            self._bar = (structure, scheme, color_bar(structure, scheme))
        return self._bar[2]

    def enabled(self, frame: Frame) -> bool:
        return self._bar_of(frame) is not None

    def run(self, frame: Frame) -> None:
        bar = self._bar_of(frame)
        self.quad.set_image(bar, lambda: legend_image(bar))
        w, h = frame.size
        qw, qh = self.quad.size
        self.quad.draw(frame.output_fbo, frame.size, w - qw - MARGIN, h - qh - MARGIN)

    def release(self) -> None:
        self.quad.release()
