"""Lines of text as RGBA images (Pillow), for what is drawn over the frame: the window's
readout and atom labels (render/window/overlay.py), the legend's title and values."""

from __future__ import annotations

from functools import lru_cache

import numpy as np
from sasprobe.render.gl.image_quad import MAX_SIZE

PADDING = 6
# DejaVu Sans has Å and ²; Pillow finds it in the system's font folders.
FONT_FILE, FONT_SIZE = "DejaVuSans.ttf", 12
_ASCII = str.maketrans({"Å": "A", "²": "^2", "·": ".", "≥": ">=", "…": "..."})


@lru_cache(maxsize=1)
def text_font():
    """(font, needs_ascii): DejaVu Sans where installed, else Pillow's own font (ASCII only)."""
    from PIL import ImageFont

    try:
        return ImageFont.truetype(FONT_FILE, FONT_SIZE), False
    except OSError:
        return ImageFont.load_default(), True


def fit_text(text: str) -> str:
    """The text as the overlay font can draw it."""
    return text.translate(_ASCII) if text_font()[1] else text


def text_image(lines: list[str]) -> np.ndarray:
    """RGBA uint8 image of the lines (white on translucent black), row 0 = top."""
    from PIL import Image, ImageDraw

    font = text_font()[0]
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
