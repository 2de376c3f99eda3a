"""An RGBA image drawn over a framebuffer at a pixel position, through a texture rewritten
only when the image changes: the window's text, the legend's colour bar."""

from __future__ import annotations

import numpy as np
from sasprobe.render.gl.uniforms import apply_uniforms

MAX_SIZE = (1024, 768)  # the texture's: room for the window's readout with its help


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
