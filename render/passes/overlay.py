"""Window-only text readout (fps, haptic rate, force, state) in the top-left corner,
drawn with Pillow's built-in font into a texture rewritten only when the text changes.
Not a pass of the chain: the window draws it over whatever the frame shows, also while
it waits for a daemon and has nothing else to show."""

from __future__ import annotations

import numpy as np

from sasprobe.render.gl.uniforms import apply_uniforms

PADDING = 6
MAX_SIZE = (640, 320)


def text_image(lines: list[str]) -> np.ndarray:
    """RGBA uint8 image of the lines (white on translucent black), row 0 = top."""
    from PIL import Image, ImageDraw, ImageFont

    font = ImageFont.load_default()
    probe = ImageDraw.Draw(Image.new("RGBA", (1, 1)))
    boxes = [probe.textbbox((0, 0), line or " ", font=font) for line in lines]
    line_h = max(b[3] - b[1] for b in boxes) + 3
    width = min(max(b[2] for b in boxes) + 2 * PADDING, MAX_SIZE[0])
    height = min(line_h * len(lines) + 2 * PADDING, MAX_SIZE[1])
    img = Image.new("RGBA", (width, height), (0, 0, 0, 150))
    draw = ImageDraw.Draw(img)
    for i, line in enumerate(lines):
        draw.text((PADDING, PADDING + i * line_h), line, fill=(255, 255, 255, 255), font=font)
    return np.asarray(img)


class TextOverlay:
    def __init__(self, ctx, programs):
        self.ctx = ctx
        self.prog = programs.get("overlay.vert", "overlay.frag")
        self.vao = ctx.vertex_array(self.prog, [])
        self.texture = ctx.texture(MAX_SIZE, 4)
        self.texture.filter = (ctx.NEAREST, ctx.NEAREST)
        self._shown: list[str] | None = None
        self._size = (0, 0)
        if "u_text" in self.prog:
            self.prog["u_text"].value = 0

    def draw(self, fbo, size: tuple[int, int], lines: list[str]) -> None:
        """Draw the lines over `fbo` (of `size` pixels), re-rasterising only changed text."""
        if not lines:
            return
        ctx = self.ctx
        if lines != self._shown:
            img = text_image(lines)
            h, w = img.shape[:2]
            self.texture.write(img.tobytes(), viewport=(0, 0, w, h))
            self._size, self._shown = (w, h), list(lines)
        w, h = self._size
        self.texture.use(0)
        apply_uniforms(self.prog, {
            "u_rect": (8.0, 8.0, float(w), float(h)),
            "u_screen": (float(size[0]), float(size[1])),
            "u_uv_scale": (w / MAX_SIZE[0], h / MAX_SIZE[1]),
        })
        fbo.use()
        fbo.viewport = (0, 0, size[0], size[1])
        ctx.enable_only(ctx.BLEND)
        ctx.blend_func = ctx.SRC_ALPHA, ctx.ONE_MINUS_SRC_ALPHA
        self.vao.render(ctx.TRIANGLE_STRIP, vertices=4)
        ctx.disable(ctx.BLEND)

    def release(self) -> None:
        self.vao.release()
        self.texture.release()
