"""The window's text over the frame: the readout (fps, haptic rate, force, state) in the
top-left corner and the picked atom's label. Drawn over whatever the window shows, also
while it waits for a daemon and has nothing else to show, so not a pass of the chain."""

from __future__ import annotations

from sasprobe.render.gl.image_quad import ImageQuad
from sasprobe.render.text import text_image


class TextOverlay:
    """Lines of text in a translucent box at a pixel position (default: the top-left corner)."""

    def __init__(self, ctx, programs):
        self.quad = ImageQuad(ctx, programs)

    def prepare(self, lines: list[str]) -> tuple[int, int]:
        """Rasterise the lines (only when they changed); their box's size in pixels."""
        self.quad.set_image(tuple(lines), lambda: text_image(lines))
        return self.quad.size

    def draw(
        self, fbo, size: tuple[int, int], lines: list[str], at: tuple[float, float] = (8.0, 8.0)
    ) -> None:
        """Draw the lines over `fbo` (of `size` pixels) with their box's top-left corner at `at`."""
        if not lines:
            return
        self.prepare(lines)
        self.quad.draw(fbo, size, *at)

    @property
    def size(self) -> tuple[int, int]:
        return self.quad.size

    def release(self) -> None:
        self.quad.release()
