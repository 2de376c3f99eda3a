"""The G-buffer layers the lighting passes read, as GL textures (the renderer's own,
render/targets.py, or made here for tests and benchmarks), and the compute-pass plumbing
the lighting passes share.

| unit | layer | format | content |
|---|---|---|---|
| 0 | position | rgba32f | world position (Å) |
| 1 | normal | rgba32f | unit world normal (a cap carries its plane's outward normal) |
| 2 | ids | rg32i | (atom index, kind): atom -1 background, -2 probe; kind as targets.KIND_* |

Row 0 of a texture is the bottom image row (GL); `download()` returns arrays in that order.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from sasprobe.render.camera import gl_bytes
from sasprobe.render.passes.base import apply_uniforms
from sasprobe.render.lighting_params import ATOM_BACKGROUND, ATOM_PROBE
from sasprobe.render.shaders import source
from sasprobe.render.targets import KIND_BACKGROUND, KIND_CAP, KIND_PROBE, KIND_SPHERE

LOCAL_SIZE = 8  # compute work-group edge of the 2D lighting passes


def texture_2d(ctx, width: int, height: int, components: int = 1, dtype: str = "f4", data: bytes | None = None):
    """A texture read with texelFetch or as an image: nearest filtering (integer textures are
    incomplete, and read as zero, with the default linear filter)."""
    import moderngl

    tex = ctx.texture((width, height), components, data=data, dtype=dtype)
    tex.filter = (moderngl.NEAREST, moderngl.NEAREST)
    tex.repeat_x = tex.repeat_y = False
    return tex


class TextureCache:
    """r32f textures by (name, size), made on first use and reused every frame (creating
    GL objects per frame is what slows moderngl programs down)."""

    def __init__(self, ctx):
        self.ctx = ctx
        self._textures: dict = {}

    def get(self, name: str, size: tuple[int, int], fill: float | None = None):
        key = (name, tuple(size))
        if key not in self._textures:
            data = None if fill is None else np.full(size[0] * size[1], fill, dtype=np.float32).tobytes()
            self._textures[key] = texture_2d(self.ctx, size[0], size[1], data=data)
        return self._textures[key]

    def release(self) -> None:
        for tex in self._textures.values():
            tex.release()
        self._textures.clear()


def read_texture(tex, components: int | None = None, dtype: str | None = None) -> np.ndarray:
    """(H, W) or (H, W, C) array of a texture, row 0 = bottom."""
    components = components or tex.components
    dtype = dtype or tex.dtype
    data = np.frombuffer(tex.read(), dtype=np.dtype(dtype)).reshape(tex.height, tex.width, components)
    return data[..., 0].copy() if components == 1 else data.copy()


def dispatch(program, width: int, height: int) -> None:
    """Run a 2D compute pass over width × height, then make its writes visible to whatever
    reads them next (texture fetch, image load, buffer read-back)."""
    program.run(group_x=(width + LOCAL_SIZE - 1) // LOCAL_SIZE, group_y=(height + LOCAL_SIZE - 1) // LOCAL_SIZE)
    program.ctx.memory_barrier()


class ComputePass:
    """A compute program over an image, with the grid bound when it has one (the lighting
    passes' base)."""

    def __init__(self, ctx, shader: str, gpu_grid=None):
        self.ctx = ctx
        self.grid = gpu_grid
        self.program = ctx.compute_shader(source(shader))

    def run(self, width: int, height: int, uniforms: dict) -> None:
        if self.grid is not None:
            self.grid.bind()
            uniforms = {**self.grid.uniforms(), **uniforms}
        apply_uniforms(self.program, uniforms)
        dispatch(self.program, width, height)

    def release(self) -> None:
        self.program.release()


@dataclass
class GBuffer:
    position: object
    normal: object
    ids: object
    owned: bool = True  # False: the renderer's targets (released by it)

    @property
    def size(self) -> tuple[int, int]:
        return self.ids.width, self.ids.height

    @classmethod
    def of_targets(cls, targets) -> "GBuffer":
        """The renderer's G-buffer (render/targets.py), read in place."""
        return cls(targets.position, targets.normal, targets.ids, owned=False)

    @classmethod
    def allocate(cls, ctx, width: int, height: int) -> "GBuffer":
        return cls(texture_2d(ctx, width, height, 4), texture_2d(ctx, width, height, 4),
                   texture_2d(ctx, width, height, 2, "i4"))

    @classmethod
    def upload(cls, ctx, position: np.ndarray, normal: np.ndarray, atom: np.ndarray) -> "GBuffer":
        """From arrays (H, W, 3), (H, W, 3), (H, W) atom ids; row 0 = bottom. Kinds follow
        from the ids: background (-1), probe (-2), sphere surface (atoms)."""
        h, w = atom.shape
        pad = np.zeros((h, w, 1), dtype=np.float32)
        pos = np.concatenate([np.asarray(position, dtype=np.float32), pad + 1.0], axis=2)
        nrm = np.concatenate([np.asarray(normal, dtype=np.float32), pad], axis=2)
        atom = np.asarray(atom, dtype=np.int32)
        kind = np.where(atom >= 0, KIND_SPHERE, np.where(atom == ATOM_PROBE, KIND_PROBE, KIND_BACKGROUND))
        ids = np.stack([atom, kind.astype(np.int32)], axis=-1)
        return cls(texture_2d(ctx, w, h, 4, data=pos.tobytes()), texture_2d(ctx, w, h, 4, data=nrm.tobytes()),
                   texture_2d(ctx, w, h, 2, "i4", data=ids.tobytes()))

    def bind(self) -> None:
        self.position.use(location=0)
        self.normal.use(location=1)
        self.ids.use(location=2)

    def download(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(position, normal, atom id), row 0 = bottom; atom ids are -1 wherever the
        lighting does not shade (background, backbone trace)."""
        ids = read_texture(self.ids)
        lit = np.isin(ids[..., 1], (KIND_SPHERE, KIND_CAP, KIND_PROBE))
        atom = np.where(lit, ids[..., 0], ATOM_BACKGROUND)
        return read_texture(self.position)[..., :3], read_texture(self.normal)[..., :3], atom

    def kinds(self) -> np.ndarray:
        return read_texture(self.ids)[..., 1]

    def release(self) -> None:
        if self.owned:
            for tex in (self.position, self.normal, self.ids):
                tex.release()


class RaycastGBuffer(ComputePass):
    """Primary rays through the grid (closest hit with clip caps) into a GBuffer."""

    def __init__(self, gpu_grid):
        super().__init__(gpu_grid.ctx, "gbuffer_raycast.comp", gpu_grid)

    def render(self, view: np.ndarray, proj: np.ndarray, width: int, height: int, out: GBuffer | None = None) -> GBuffer:
        gbuffer = out or GBuffer.allocate(self.ctx, width, height)
        gbuffer.position.bind_to_image(0, read=False, write=True)
        gbuffer.normal.bind_to_image(1, read=False, write=True)
        gbuffer.ids.bind_to_image(2, read=False, write=True)
        self.run(width, height, {
            "u_inv_proj": gl_bytes(np.linalg.inv(proj)),
            "u_inv_view": gl_bytes(np.linalg.inv(view)),
        })
        return gbuffer
