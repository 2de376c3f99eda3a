"""The uniform grid (molecule/grid.py) uploaded to the GPU, with the culling (culling.py)
and the probe that the shaders read beside it.

`UploadedGrid` uploads, once per molecule, the grid built with the *expanded* radii (vdW +
probe, the grid the daemon uses) as std430 shader-storage buffers, and the per-atom
tables as images (render/gl/textures.py table_image: llvmpipe reads an image far faster
than a storage buffer):

    buffer 0  cell_start  uint32[n_cells + 1], CSR offsets
    buffer 1  cell_atoms  uint32[], sphere indices per cell
    image 4   spheres     rgba32f per atom: centre (Å, float32), van der Waals radius
    image 5   culled      r32ui per atom, flags: bit 0 = nothing of the atom is kept (it casts
                          no shadow and occludes nothing); bit 1 = its centre is clipped away
                          (analytic AO skips it)

`culled` is rewritten (n_atoms × 4 bytes) whenever a clip plane or the cube moves; the rest
stays until the molecule changes. Shaders read them through shaders/grid_traversal.glsl.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from sasprobe.molecule.grid import UniformGrid
from sasprobe.render.gl.textures import table_image
from sasprobe.render.lighting.culling import Culling
from sasprobe.render.lighting.light_buffer import DirectionalLightBuffer

BINDING_CELL_START, BINDING_CELL_ATOMS = 0, 1  # storage buffers
IMAGE_SPHERES, IMAGE_CULLED = 4, 5  # image units (shaders/grid_traversal.glsl)
NO_PROBE = (0.0, 0.0, 0.0, 0.0)
UNBOUNDED = 1e30  # Å: a probe whose share of the AO is not windowed
CULLED, CENTRE_CLIPPED = 1, 2  # flag bits of the culled buffer


class UploadedGrid:
    """A UniformGrid's buffers on one moderngl context, with the per-atom culled flags and
    the probe as an occluder."""

    def __init__(self, ctx, grid: UniformGrid, vdw_radii: np.ndarray):
        vdw_radii = np.asarray(vdw_radii, dtype=np.float64).reshape(-1)
        if vdw_radii.shape[0] != grid.centers.shape[0]:
            raise ValueError("one vdW radius per grid sphere is needed")
        if np.any(vdw_radii > grid.radii):
            raise ValueError(
                "the grid must be built with radii at least the vdW radii (vdW + probe)"
            )
        self.ctx = ctx
        self.grid = grid
        self.n_atoms = int(vdw_radii.shape[0])
        self.vdw_radii = vdw_radii
        # Thickest soft-shadow shell the grid still holds: the smallest expansion.
        self.max_shell = float(np.min(grid.radii - vdw_radii))
        # Each atom's centre and vdW radius as the shaders read them (the light buffers list
        # rows of it).
        self.sphere_rows = np.column_stack([grid.centers, vdw_radii]).astype(np.float32)
        # Zero-length buffers cannot be created; an all-empty grid still gets one entry.
        atoms = grid.cell_atoms if grid.cell_atoms.size else np.zeros(1, dtype=np.uint32)
        self.cell_start = ctx.buffer(grid.cell_start.astype(np.uint32).tobytes())
        self.cell_atoms = ctx.buffer(atoms.astype(np.uint32).tobytes())
        self.spheres = table_image(ctx, None, self.sphere_rows)
        self.culled = table_image(ctx, None, np.zeros(self.n_atoms, dtype=np.uint32), "u4")
        self.culling = Culling()
        self.culled_mask = np.zeros(self.n_atoms, dtype=bool)
        self.centre_clipped_mask = np.zeros(self.n_atoms, dtype=bool)
        self.walk_range = (np.zeros(3, dtype=np.int64), grid.dims - 1)
        self.probe_sphere = NO_PROBE
        self.probe_reach = UNBOUNDED
        self._sun_buffer: DirectionalLightBuffer | None = None  # see sun_buffer()
        # Counts set_culling calls (what depends on the culled flags follows it)
        self.culling_version = 0
        # (culling version, the uniforms that follow it)
        self._uniforms: tuple[int, dict] = (
            -1,
            {},
        )

    @classmethod
    def from_structure(
        cls, ctx, structure, probe_radius: float, cell_size: float | None = None
    ) -> UploadedGrid:
        grid = UniformGrid(structure.positions, structure.expanded_radii(probe_radius), cell_size)
        return cls(ctx, grid, structure.vdw_radii)

    @property
    def nbytes(self) -> int:
        """GPU memory of the grid and sphere buffers (bytes)."""
        tables = sum(t.width * t.height * t.components * 4 for t in (self.spheres, self.culled))
        return self.cell_start.size + self.cell_atoms.size + tables

    def set_culling(self, culling: Culling) -> None:
        """Clip planes / navigation cube moved: refresh the culled flags and the walk range."""
        self.culling = culling
        self.culling_version += 1
        self.culled_mask = culling.culled_atoms(self.grid.centers, self.vdw_radii, self.grid)
        self.centre_clipped_mask = culling.centre_clipped(self.grid.centers)
        flags = np.where(self.culled_mask, CULLED, 0) | np.where(
            self.centre_clipped_mask, CENTRE_CLIPPED, 0
        )
        self.culled = table_image(self.ctx, self.culled, flags.astype(np.uint32), "u4")
        box = culling.cube_box
        rng = self.grid.cell_range(*box) if box is not None else None
        if box is not None and rng is None:  # the cube is off the molecule: walk one cell
            rng = (np.zeros(3, dtype=np.int64), np.zeros(3, dtype=np.int64))
        self.walk_range = (
            rng if rng is not None else (np.zeros(3, dtype=np.int64), self.grid.dims - 1)
        )

    def set_probe(
        self, center: np.ndarray | None, radius: float = 0.0, reach: float = UNBOUNDED
    ) -> None:
        """The probe sphere as an occluder (None: no probe); its analytic share of the AO is
        windowed to 0 at `reach` Å from its centre (the renderer passes its light's range)."""
        self.probe_sphere = (
            NO_PROBE if center is None else (*(float(v) for v in center), float(radius))
        )
        self.probe_reach = float(reach)

    def bind(self) -> None:
        self.cell_start.bind_to_storage_buffer(BINDING_CELL_START)
        self.cell_atoms.bind_to_storage_buffer(BINDING_CELL_ATOMS)
        self.spheres.bind_to_image(IMAGE_SPHERES, read=True, write=False)
        self.culled.bind_to_image(IMAGE_CULLED, read=True, write=False)

    def uniforms(self) -> dict[str, object]:
        if self._uniforms[0] != self.culling_version:
            lo, hi = self.walk_range
            self._uniforms = (
                self.culling_version,
                {
                    "u_grid_origin": tuple(float(v) for v in self.grid.origin),
                    "u_cell_size": float(self.grid.cell_size),
                    "u_grid_dims": tuple(int(v) for v in self.grid.dims),
                    "u_walk_lo": tuple(int(v) for v in lo),
                    "u_walk_hi": tuple(int(v) for v in hi),
                    **self.culling.uniforms(),
                },
            )
        return {
            **self._uniforms[1],
            "u_probe_sphere": self.probe_sphere,
            "u_probe_reach": self.probe_reach,
        }

    def sun_buffer(self) -> DirectionalLightBuffer:
        """The directional light's buffer of these spheres (render/lighting/light_buffer.py),
        made on first use and shared by every pass that traces the sun (the shadow pass, the
        occlusion atlas's bake), so a light and a culling are listed once."""
        if self._sun_buffer is None:
            self._sun_buffer = DirectionalLightBuffer(self)
        return self._sun_buffer

    def release(self) -> None:
        for b in (self.cell_start, self.cell_atoms, self.spheres, self.culled):
            b.release()
        if self._sun_buffer is not None:
            self._sun_buffer.release()


@dataclass
class GridWalks:
    """Cells a batch of rays visited on the GPU (the DDA test hook's answer)."""

    counts: np.ndarray  # (R,) cells visited per ray (may exceed max_visits: then truncated)
    cells: np.ndarray  # (R, max_visits, 3) int
    t: np.ndarray  # (R, max_visits, 2) float32: t_enter, t_exit

    def ray(self, i: int) -> tuple[np.ndarray, np.ndarray]:
        n = min(int(self.counts[i]), self.cells.shape[1])
        return self.cells[i, :n], self.t[i, :n]


def walk_rays_on_gpu(
    gpu_grid: UploadedGrid,
    origins,
    directions,
    t_min=0.0,
    t_max=1e30,
    max_visits: int = 256,
    walk_range: tuple[np.ndarray, np.ndarray] | None = None,
) -> GridWalks:
    """Test hook: walk rays o + t d through the grid with the shaders' DDA
    (grid_walk_probe.comp)."""
    from sasprobe.render.gl.programs import source
    from sasprobe.render.gl.uniforms import apply_uniforms

    ctx = gpu_grid.ctx
    origins = np.asarray(origins, dtype=np.float64).reshape(-1, 3)
    directions = np.asarray(directions, dtype=np.float64).reshape(-1, 3)
    n = origins.shape[0]
    rays = np.zeros((n, 8), dtype=np.float32)
    rays[:, :3], rays[:, 3] = origins, t_min
    rays[:, 4:7], rays[:, 7] = directions, t_max
    program = ctx.compute_shader(source("grid_walk_probe.comp"))
    buffers = [
        ctx.buffer(rays.tobytes()),
        ctx.buffer(reserve=max(n * max_visits * 16, 16)),
        ctx.buffer(reserve=max(n * max_visits * 8, 8)),
        ctx.buffer(reserve=max(n * 4, 4)),
    ]
    try:
        gpu_grid.bind()
        for binding, buffer in enumerate(buffers, start=4):
            buffer.bind_to_storage_buffer(binding)
        uniforms = gpu_grid.uniforms()
        if walk_range is not None:
            uniforms["u_walk_lo"] = tuple(int(v) for v in walk_range[0])
            uniforms["u_walk_hi"] = tuple(int(v) for v in walk_range[1])
        apply_uniforms(program, {**uniforms, "u_n_rays": n, "u_max_visits": max_visits})
        program.run(group_x=(n + 63) // 64)
        ctx.memory_barrier()
        cells = np.frombuffer(buffers[1].read(), dtype=np.int32)[: n * max_visits * 4].reshape(
            n, max_visits, 4
        )
        t = np.frombuffer(buffers[2].read(), dtype=np.float32)[: n * max_visits * 2].reshape(
            n, max_visits, 2
        )
        counts = np.frombuffer(buffers[3].read(), dtype=np.int32)[:n].copy()
    finally:
        for buffer in buffers:
            buffer.release()
        program.release()
    return GridWalks(counts, cells[..., :3].astype(np.int64), t)
