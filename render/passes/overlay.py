"""Images over the frame: the window's text readout (fps, haptic rate, force, state) in
the top-left corner and the picked atom's label, drawn with Pillow's built-in font into a
texture rewritten only when the text changes (the legend pass draws its colour bar the
same way). Not a pass of the chain: the window draws text over whatever the frame shows,
also while it waits for a daemon and has nothing else to show."""

from __future__ import annotations

from functools import lru_cache

import numpy as np
from sasprobe.render.gl.uniforms import apply_uniforms

PADDING = 6
MAX_SIZE = (1024, 768)  # an overlay's texture: room for the readout with the window's help
FONT_FILE, FONT_SIZE = (
    "DejaVuSans.ttf",
    12,
)  # has Å and ²; Pillow finds it in the system's font folders
_ASCII = str.maketrans({"Å": "A", "²": "^2", "·": ".", "≥": ">=", "…": "..."})


@lru_cache(maxsize=1)
def overlay_font():
    """(font, needs_ascii): DejaVu Sans where installed, else Pillow's own font (ASCII only)."""
    from PIL import ImageFont

    try:
        return ImageFont.truetype(FONT_FILE, FONT_SIZE), False
    except OSError:
        return ImageFont.load_default(), True


def fit_text(text: str) -> str:
    """The text as the overlay font can draw it."""
    return text.translate(_ASCII) if overlay_font()[1] else text


def text_image(lines: list[str]) -> np.ndarray:
    """RGBA uint8 image of the lines (white on translucent black), row 0 = top."""
    from PIL import Image, ImageDraw

    font = overlay_font()[0]
    lines = [fit_text(line) for line in lines]
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


class ImageQuad:
    """An RGBA image (row 0 = top, at most MAX_SIZE) drawn over a framebuffer at a pixel
    position; the texture is rewritten only when the image changes."""

    def __init__(self, ctx, programs):
        self.ctx = ctx
        self.prog = programs.get("overlay.vert", "overlay.frag")
        self.vao = ctx.vertex_array(self.prog, [])
        self.texture = ctx.texture(MAX_SIZE, 4)
        self.texture.filter = (ctx.NEAREST, ctx.NEAREST)
        self.key: object = None  # what the texture shows
        self.size = (0, 0)
        if "u_text" in self.prog:
            self.prog["u_text"].value = 0

    def set_image(self, key, make_image) -> None:
        """Upload make_image() unless the texture already shows `key`."""
        if key == self.key:
            return
        img = make_image()[: MAX_SIZE[1], : MAX_SIZE[0]]
        h, w = img.shape[:2]
        self.texture.write(np.ascontiguousarray(img).tobytes(), viewport=(0, 0, w, h))
        self.size, self.key = (w, h), key

    def draw(self, fbo, screen: tuple[int, int], x: float, y: float) -> None:
        """Draw at (x, y): the image's top-left corner, pixels from the top-left of `fbo`."""
        ctx = self.ctx
        w, h = self.size
        self.texture.use(0)
        apply_uniforms(
            self.prog,
            {
                "u_rect": (float(x), float(y), float(w), float(h)),
                "u_screen": (float(screen[0]), float(screen[1])),
                "u_uv_scale": (w / MAX_SIZE[0], h / MAX_SIZE[1]),
            },
        )
        fbo.use()
        fbo.viewport = (0, 0, screen[0], screen[1])
        ctx.enable_only(ctx.BLEND)
        ctx.blend_func = ctx.SRC_ALPHA, ctx.ONE_MINUS_SRC_ALPHA
        self.vao.render(ctx.TRIANGLE_STRIP, vertices=4)
        ctx.disable(ctx.BLEND)

    def release(self) -> None:
        self.vao.release()
        self.texture.release()


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
