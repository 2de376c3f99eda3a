"""Textures made for compute passes, reused per size, the one way pixels come back to numpy,
and the one way framebuffers are released.

GL keeps row 0 at the bottom of an image; `read_texture(..., top_first=True)` and
`read_image` return row 0 = the top row, as images and the G-buffer export are stored.
"""

from __future__ import annotations

import numpy as np


def release_framebuffers(ctx, *fbos) -> None:
    """Release framebuffers, leaving the default one bound if one of them is: moderngl
    binds the framebuffer it last used again when it makes a new one, and binding a deleted
    one is a GL_INVALID_OPERATION."""
    if any(ctx.fbo is fbo for fbo in fbos):
        ctx.detect_framebuffer(0).use()
    for fbo in fbos:
        fbo.release()


def texture_2d(
    ctx, width: int, height: int, components: int = 1, dtype: str = "f4", data: bytes | None = None
):
    """A texture read with texelFetch or as an image: nearest filtering (integer textures are
    incomplete, and read as zero, with the default linear filter)."""
    import moderngl

    tex = ctx.texture((width, height), components, data=data, dtype=dtype)
    tex.filter = (moderngl.NEAREST, moderngl.NEAREST)
    tex.repeat_x = tex.repeat_y = False
    return tex


def steady_side(n: int) -> int:
    """A side of `n` texels, or a little more where n is a power of two, for textures whose
    size follows the scene (a cube's atoms, a light's lists): llvmpipe compiles a variant of
    every shader that reads a texture per power-of-two-ness of its sides (its sampler key's
    pot bits), and compiling it stalls the frame a cube moving across such a size is in."""
    return max(n + 1, 3) if n & (n - 1) == 0 else n


TABLE_ROW = 4096  # entries a row of a table image (shaders/table_image.glsl TABLE_ROW_BITS)


def _filled_rows(entries: int) -> int:
    return max(1, -(-entries // TABLE_ROW))


def table_rows(entries: int) -> int:
    """The rows of a table image with room for `entries` (a steady side: see steady_side)."""
    return steady_side(_filled_rows(entries))


def table_image(ctx, texture, table: np.ndarray, dtype: str = "f4"):
    """`table` (n, components) as an image that shaders read entry by entry
    (shaders/table_image.glsl: entry k at (k % TABLE_ROW, k // TABLE_ROW)), written into
    `texture` when it has the rows (else it is released and made again); returns the texture.
    Only the rows that hold entries are written: shaders never read past the table's end."""
    n, components = table.shape[0], table.shape[1] if table.ndim > 1 else 1
    used, rows = _filled_rows(n), table_rows(n)
    if (
        texture is None
        or texture.height < rows
        or texture.components != components
        or texture.dtype != dtype
    ):
        if texture is not None:
            texture.release()
        texture = texture_2d(ctx, TABLE_ROW, rows, components, dtype)
    padded = np.zeros((used * TABLE_ROW, components), dtype=table.dtype)
    padded[:n] = table.reshape(n, components)
    texture.write(padded.tobytes(), viewport=(0, 0, TABLE_ROW, used))
    return texture


def write_table_rows(texture, table: np.ndarray, entries: np.ndarray) -> None:
    """Write into a table image (table_image's layout) the rows holding `entries` (indices
    into the flat, one-component `table`), each run of consecutive rows at once."""
    rows = np.unique(np.asarray(entries, dtype=np.int64) // TABLE_ROW)
    if rows.size == 0:
        return
    breaks = np.flatnonzero(np.diff(rows) > 1)
    for first, last in zip(np.r_[rows[0], rows[breaks + 1]], np.r_[rows[breaks], rows[-1]]):
        block = np.zeros((int(last - first) + 1) * TABLE_ROW, dtype=table.dtype)
        piece = table[int(first) * TABLE_ROW : (int(last) + 1) * TABLE_ROW]
        block[: piece.size] = piece
        texture.write(block.tobytes(), viewport=(0, int(first), TABLE_ROW, int(last - first) + 1))


class TextureCache:
    """r32f textures by (name, size), made on first use and reused every frame (creating
    GL objects per frame is what slows moderngl programs down)."""

    def __init__(self, ctx):
        self.ctx = ctx
        self._textures: dict = {}
        self._framebuffers: dict = {}

    def get(self, name: str, size: tuple[int, int], fill: float | None = None):
        key = (name, tuple(size))
        if key not in self._textures:
            data = (
                None
                if fill is None
                else np.full(size[0] * size[1], fill, dtype=np.float32).tobytes()
            )
            self._textures[key] = texture_2d(self.ctx, size[0], size[1], data=data)
        return self._textures[key]

    def fill(self, name: str, size: tuple[int, int], value: float):
        """The texture `name`, cleared to `value` on the GPU (no upload)."""
        key = (name, tuple(size))
        if key not in self._framebuffers:
            self._framebuffers[key] = self.ctx.framebuffer([self.get(name, size)])
        self._framebuffers[key].clear(value, value, value, value)
        return self._textures[key]

    def release(self) -> None:
        release_framebuffers(self.ctx, *self._framebuffers.values())
        for tex in self._textures.values():
            tex.release()
        self._framebuffers.clear()
        self._textures.clear()


def read_texture(tex, top_first: bool = False) -> np.ndarray:
    """(H, W) or (H, W, C) copy of a texture in its own dtype (normalised bytes "f1" as
    uint8); row 0 = bottom unless `top_first`."""
    dtype = np.uint8 if tex.dtype == "f1" else np.dtype(tex.dtype)
    data = np.frombuffer(tex.read(), dtype=dtype).reshape(tex.height, tex.width, tex.components)
    if top_first:
        data = data[::-1]
    return data[..., 0].copy() if tex.components == 1 else data.copy()


def read_image(fbo, size: tuple[int, int]) -> np.ndarray:
    """A framebuffer's colour as H x W x 3 uint8, row 0 = top (the window's screen, or an
    offscreen target)."""
    w, h = size
    data = np.frombuffer(fbo.read(viewport=(0, 0, w, h), components=3), dtype=np.uint8)
    return data.reshape(h, w, 3)[::-1].copy()
