"""Render targets of one frame size: the G-buffer, the visibility buffer the light pass
multiplies by, the lit colour and the final image. Created once per size, reused
every frame (no per-frame GL allocation).

G-buffer attachments (shaders/gbuffer_out.glsl writes them in this order):
    0 albedo    RGBA8    CPK colour
    1 position  RGBA32F  world position, Å (w = 1 where covered)
    2 normal    RGBA32F  world unit normal (caps: the cutting plane's outward normal)
    3 ids       RG32I    (atom id, kind); atom id -1 background, -2 probe; kind KIND_*
    depth       24-bit depth texture
Visibility (RGBA16F, cleared to 1): r directional-light visibility, g probe-light
visibility, b ambient accessibility. Lighting passes draw into `visibility_fbo`
(with a colour mask for their channel) before the light pass reads it.
"""

from __future__ import annotations

import numpy as np

KIND_BACKGROUND = 0
KIND_SPHERE = 1
KIND_CAP = 2
KIND_BACKBONE = 3
KIND_PROBE = 4
PROBE_ID = -2


class RenderTargets:
    def __init__(self, ctx, size: tuple[int, int]):
        self.ctx = ctx
        self.size = (int(size[0]), int(size[1]))
        w_h = self.size
        self.albedo = ctx.texture(w_h, 4, dtype="f1")
        self.position = ctx.texture(w_h, 4, dtype="f4")
        self.normal = ctx.texture(w_h, 4, dtype="f4")
        self.ids = ctx.texture(w_h, 2, dtype="i4")
        self.depth = ctx.depth_texture(w_h)
        self.visibility = ctx.texture(w_h, 4, dtype="f2")
        self.lit = ctx.texture(w_h, 4, dtype="f1")  # light pass output, FXAA input
        self.final = ctx.texture(w_h, 4, dtype="f1")  # headless output
        for tex in (self.albedo, self.position, self.normal, self.ids, self.visibility):
            tex.filter = (ctx.NEAREST, ctx.NEAREST)
        self.lit.filter = (ctx.LINEAR, ctx.LINEAR)
        self.lit.repeat_x = self.lit.repeat_y = False
        self.gbuffer_fbo = ctx.framebuffer([self.albedo, self.position, self.normal, self.ids], self.depth)
        self.visibility_fbo = ctx.framebuffer([self.visibility])
        # Forward passes after lighting (the cube wire) test against the G-buffer depth.
        self.lit_fbo = ctx.framebuffer([self.lit], self.depth)
        self.final_fbo = ctx.framebuffer([self.final])

    def clear_visibility(self) -> None:
        self.visibility_fbo.use()
        self.visibility_fbo.clear(1.0, 1.0, 1.0, 1.0)

    def read(self, texture, components: int, dtype) -> np.ndarray:
        """A texture as H x W x components, row 0 = top of the image."""
        w, h = self.size
        data = np.frombuffer(texture.read(), dtype=dtype).reshape(h, w, components)
        return data[::-1].copy()

    def release(self) -> None:
        for obj in (self.gbuffer_fbo, self.visibility_fbo, self.lit_fbo, self.final_fbo, self.albedo,
                    self.position, self.normal, self.ids, self.depth, self.visibility, self.lit, self.final):
            obj.release()
