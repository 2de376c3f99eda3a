"""The G-buffer layers the lighting passes read, as GL textures: the renderer's own
(render/gl/targets.py), or made here for tests and benchmarks (uploaded from arrays, or
ray cast through the grid by RaycastGBuffer).

    unit  layer     format   content
    0     position  rgba32f  world position (Å)
    1     normal    rgba32f  unit world normal (a cap carries its plane's outward normal)
    2     ids       rg32i    (atom index, kind): atom ATOM_BACKGROUND (-1), ATOM_PROBE (-2);
                             kind KIND_* (render/gl/targets.py)

Row 0 of a texture is the bottom image row (GL); `download()` returns arrays in that order.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from sasprobe.render.gl.compute import ComputeProgram
from sasprobe.render.gl.targets import (
    ATOM_BACKGROUND,
    ATOM_PROBE,
    KIND_BACKGROUND,
    KIND_CAP,
    KIND_PROBE,
    KIND_SPHERE,
)
from sasprobe.render.gl.textures import read_texture, texture_2d
from sasprobe.render.gl.uniforms import gl_bytes


@dataclass
class GBuffer:
    position: object
    normal: object
    ids: object
    owned: bool = True  # False: the renderer's targets (released by it)
    # The renderer's depth texture (1 on background pixels), where there is one.
    depth: object = None

    @property
    def size(self) -> tuple[int, int]:
        return self.ids.width, self.ids.height

    @classmethod
    def of_targets(cls, targets) -> GBuffer:
        """The renderer's G-buffer (render/gl/targets.py), read in place."""
        return cls(targets.position, targets.normal, targets.ids, owned=False, depth=targets.depth)

    @classmethod
    def allocate(cls, ctx, width: int, height: int) -> GBuffer:
        return cls(
            texture_2d(ctx, width, height, 4),
            texture_2d(ctx, width, height, 4),
            texture_2d(ctx, width, height, 2, "i4"),
        )

    @classmethod
    def upload(cls, ctx, position: np.ndarray, normal: np.ndarray, atom: np.ndarray) -> GBuffer:
        """From arrays (H, W, 3), (H, W, 3), (H, W) atom ids; row 0 = bottom. Kinds follow
        from the ids: background (-1), probe (-2), sphere surface (atoms)."""
        h, w = atom.shape
        pad = np.zeros((h, w, 1), dtype=np.float32)
        pos = np.concatenate([np.asarray(position, dtype=np.float32), pad + 1.0], axis=2)
        nrm = np.concatenate([np.asarray(normal, dtype=np.float32), pad], axis=2)
        atom = np.asarray(atom, dtype=np.int32)
        kind = np.where(
            atom >= 0, KIND_SPHERE, np.where(atom == ATOM_PROBE, KIND_PROBE, KIND_BACKGROUND)
        )
        ids = np.stack([atom, kind.astype(np.int32)], axis=-1)
        return cls(
            texture_2d(ctx, w, h, 4, data=pos.tobytes()),
            texture_2d(ctx, w, h, 4, data=nrm.tobytes()),
            texture_2d(ctx, w, h, 2, "i4", data=ids.tobytes()),
        )

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


class RaycastGBuffer(ComputeProgram):
    """Primary rays through the grid (closest hit with clip caps) into a GBuffer."""

    def __init__(self, gpu_grid):
        super().__init__(gpu_grid.ctx, "gbuffer_raycast.comp", gpu_grid)

    def render(
        self,
        view: np.ndarray,
        proj: np.ndarray,
        width: int,
        height: int,
        out: GBuffer | None = None,
    ) -> GBuffer:
        gbuffer = out or GBuffer.allocate(self.ctx, width, height)
        gbuffer.position.bind_to_image(0, read=False, write=True)
        gbuffer.normal.bind_to_image(1, read=False, write=True)
        gbuffer.ids.bind_to_image(2, read=False, write=True)
        self.run(
            width,
            height,
            {
                "u_inv_proj": gl_bytes(np.linalg.inv(proj)),
                "u_inv_view": gl_bytes(np.linalg.inv(view)),
            },
        )
        return gbuffer
