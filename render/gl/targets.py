"""Render targets of one frame size: the G-buffer, the visibility buffer the shading pass
multiplies by, the lit colour and the final image. Created once per size, reused
every frame (no per-frame GL allocation).

G-buffer attachments (shaders/gbuffer_out.glsl writes them in this order):
    0 albedo    RGBA8    CPK colour
    1 position  RGBA32F  world position, Å (w = 1 where covered)
    2 normal    RGBA32F  world unit normal (caps: the cutting plane's outward normal)
    3 ids       RG32I    (atom id, kind): an atom index, ATOM_BACKGROUND or ATOM_PROBE; KIND_*
    depth       24-bit depth texture
Visibility (RGBA32F, cleared to 1): r directional-light visibility, g 1 (the probe light's
visibility is a texture of the lighting's own, handed to the shading pass with the frame:
render/passes/base.py ProbeLighting), b ambient accessibility, a edge factor. The lighting
pass writes it before the shading pass reads it. Float32, not 16: a frame drawn from the
kept molecule layer multiplies the probe's share of the AO in after it, a whole frame
before, and only at full precision do both round alike (FXAA turns a 1/255 difference at
an edge into several).

The ids below are the one home of these numbers: the shaders get them as #defines
(render/gl/programs.py generates constants.glsl from them), the export and the lighting
passes import them.
"""

from __future__ import annotations

import numpy as np
from sasprobe.render.gl.textures import read_texture, release_framebuffers

ATOM_BACKGROUND = -1  # atom id of background pixels
ATOM_PROBE = -2  # atom id of the probe sphere's pixels
KIND_BACKGROUND = 0
KIND_SPHERE = 1
KIND_CAP = 2  # a sphere's cut face (clip plane, cube face or near plane)
KIND_BACKBONE = 3
KIND_PROBE = 4


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
        self.visibility = ctx.texture(w_h, 4, dtype="f4")
        self.lit = ctx.texture(w_h, 4, dtype="f1")  # shading pass output, FXAA input
        self.final = ctx.texture(w_h, 4, dtype="f1")  # headless output
        for tex in (self.albedo, self.position, self.normal, self.ids, self.visibility):
            tex.filter = (ctx.NEAREST, ctx.NEAREST)
        self.lit.filter = (ctx.LINEAR, ctx.LINEAR)
        self.lit.repeat_x = self.lit.repeat_y = False
        self.gbuffer_fbo = ctx.framebuffer(
            [self.albedo, self.position, self.normal, self.ids], self.depth
        )
        # The clear pass's: ids cannot take a float clear
        self.ids_fbo = ctx.framebuffer([self.ids])
        self.visibility_fbo = ctx.framebuffer([self.visibility])
        # Forward passes after lighting (the cube wire) test against the G-buffer depth.
        self.lit_fbo = ctx.framebuffer([self.lit], self.depth)
        self.final_fbo = ctx.framebuffer([self.final])
        self._kept: dict[str, tuple[object, object]] = {}  # name -> (texture, framebuffer)

    def kept_picture(self, name: str):
        """The framebuffer of an RGBA8 picture of this size kept across frames under `name`
        (the layered frames' shaded and antialiased pictures), made on first use."""
        if name not in self._kept:
            texture = self.ctx.texture(self.size, 4, dtype="f1")
            self._kept[name] = (texture, self.ctx.framebuffer([texture]))
        return self._kept[name][1]

    def clear_visibility(self) -> None:
        self.visibility_fbo.use()
        self.visibility_fbo.clear(1.0, 1.0, 1.0, 1.0)

    def read_pixel(self, x: int, y: int) -> tuple[int, int, np.ndarray]:
        """(atom id, kind, world position) of the G-buffer at pixel (x, y), y from the top:
        what a click on the image shows (clicks and zooms read one texel, not the buffer)."""
        w, h = self.size
        x, y = min(max(int(x), 0), w - 1), min(max(int(y), 0), h - 1)
        viewport = (x, h - 1 - y, 1, 1)
        ids = np.frombuffer(
            self.gbuffer_fbo.read(viewport=viewport, components=2, attachment=3, dtype="i4"),
            dtype=np.int32,
        )
        position = np.frombuffer(
            self.gbuffer_fbo.read(viewport=viewport, components=3, attachment=1, dtype="f4"),
            dtype=np.float32,
        )
        return int(ids[0]), int(ids[1]), position.astype(np.float64)

    def read(self, texture) -> np.ndarray:
        """One of these textures as H x W (x components), row 0 = top of the image."""
        return read_texture(texture, top_first=True)

    def release(self) -> None:
        release_framebuffers(
            self.ctx,
            self.gbuffer_fbo,
            self.ids_fbo,
            self.visibility_fbo,
            self.lit_fbo,
            self.final_fbo,
            *(fbo for _, fbo in self._kept.values()),
        )
        for tex in (
            self.albedo,
            self.position,
            self.normal,
            self.ids,
            self.depth,
            self.visibility,
            self.lit,
            self.final,
            *(tex for tex, _ in self._kept.values()),
        ):
            tex.release()
