"""QuteMol's precomputed occlusion (Tarini, Cignoni, Montani, IEEE TVCG 2006): each drawn
atom gets a patch of P x P texels over its sphere (octahedral parametrisation) holding its
ambient accessibility and, for lights fixed in the molecule frame, its visibility of the
directional light and of the probe's light. Patches are baked once per structure and per
culling change (a light's channel again when that light moves), so a frame costs one
bilinear lookup per pixel whatever the camera does.

The patch layout is pyQuteMol's (MDAnalysis/pyQuteMol @6d45ec9f, python/OctaMap.py getDir:
texel centres on the patch border). Where QuteMol rendered 128 shadow maps
(python/hardSettings.py N_VIEW_DIR), the bake here traces rays through the grid, in chunks
of CHUNK_SLOTS atoms and four steps (shaders/atlas_*.comp): gather each atom's neighbours
(KeptCells), mark per direction the neighbours its rays can meet, test those for the texels
facing the direction (atlas_tables.facing_masks), and sum. Rays are `AOSettings.distance`
long, as the ray-traced AO's, so both converge to the same accessibility. What the steps
keep in images and uniform blocks is what llvmpipe would otherwise load lane by lane from
a storage buffer. docs/rendering.md walks through the bake.
"""

from __future__ import annotations

import logging
import math
import time

import numpy as np
from sasprobe.render.gl.compute import ComputeProgram, ComputeVariants
from sasprobe.render.gl.depth_picked import DepthPickedDraw
from sasprobe.render.gl.textures import TextureCache, steady_side, table_image
from sasprobe.render.gl.uniforms import apply_uniforms
from sasprobe.render.lighting.ao.atlas_tables import (
    clustered,
    facing_masks,
    fibonacci_directions,
    texel_normals,
)
from sasprobe.render.lighting.gbuffer import GBuffer
from sasprobe.render.lighting.settings import (
    DIRECTION_RANGE,
    PointLight,
    light_uniforms,
    ray_epsilon_uniforms,
)

log = logging.getLogger("sasprobe")

CHUNK_SLOTS = 1024  # atoms per bake dispatch, at most
MAX_SCRATCH_BYTES = 256 * 2**20  # the bake's storage per chunk, at most
MAX_NEIGHBOURS, MAX_OVERLAPS = 1024, 32  # as shaders/atlas_ray_buffers.glsl
MASK_WORDS, MAX_PATCH_TEXELS = MAX_NEIGHBOURS // 32, 64 * 64
BINDING_TEXEL_NORMALS, BINDING_DIRECTIONS = 0, 1  # uniform blocks
MAX_DIRECTIONS = DIRECTION_RANGE[1]  # as shaders/atlas_sum_buffers.glsl
BINDING_FACING_MASKS, BINDING_FACING_DIRECTIONS = 16, 17
MAX_ATLAS_BYTES = 512 * 2**20
BINDING_SLOT_ATOMS, BINDING_ATOM_SLOTS = 4, 4
BINDING_KEPT_START, BINDING_SLOT_ENTRY = 13, 15  # shaders/atlas_gather.comp
# Image units (the atlas itself is unit 0): the neighbours (shaders/atlas_ray_buffers.glsl),
# the overlaps and the kept spheres (shaders/atlas_gather.comp).
IMAGE_NEIGHBOURS, IMAGE_OVERLAPS, IMAGE_KEPT_SPHERES = 1, 2, 3
LOCAL = 64  # the bake shaders' local_size_x


class KeptCells:
    """The spheres the culling keeps, each stored once in the cell of its centre (cells of
    the uploaded grid's size over the kept atoms' box), for the bake's neighbour gather: the grid
    proper stores every sphere in each cell its expanded sphere overlaps, and culled atoms
    with the rest, so most of what a gather read there was thrown away."""

    def __init__(self, ctx, centers: np.ndarray, radii: np.ndarray, cell: float):
        n = centers.shape[0]
        self.origin = centers.min(axis=0) if n else np.zeros(3)
        self.cell = float(cell)
        cells3 = np.floor((centers - self.origin) / self.cell).astype(np.int64)
        self.dims = cells3.max(axis=0) + 1 if n else np.ones(3, dtype=np.int64)
        flat = cells3[:, 0] + self.dims[0] * (cells3[:, 1] + self.dims[1] * cells3[:, 2])
        order = np.argsort(flat, kind="stable")
        start = np.zeros(int(np.prod(self.dims)) + 1, dtype=np.uint32)
        np.cumsum(np.bincount(flat, minlength=start.size - 1), out=start[1:])
        entry = np.empty(n, dtype=np.uint32)
        entry[order] = np.arange(n, dtype=np.uint32)
        self.spheres = table_image(
            ctx, None, np.column_stack([centers, radii]).astype(np.float32)[order]
        )
        self.buffers = {
            BINDING_KEPT_START: ctx.buffer(start.tobytes()),
            BINDING_SLOT_ENTRY: ctx.buffer(entry.tobytes() if n else b"\0" * 4),
        }

    def bind(self) -> None:
        for binding, buffer in self.buffers.items():
            buffer.bind_to_storage_buffer(binding)
        self.spheres.bind_to_image(IMAGE_KEPT_SPHERES, read=True, write=False)

    def uniforms(self) -> dict:
        return {
            "u_kept_origin": tuple(float(v) for v in self.origin),
            "u_kept_cell": self.cell,
            "u_kept_dims": tuple(int(v) for v in self.dims),
        }

    def release(self) -> None:
        for buffer in self.buffers.values():
            buffer.release()
        self.spheres.release()


class OcclusionAtlas:
    """The patches of one uploaded grid's drawn atoms, and the passes that bake and read them."""

    def __init__(self, gpu_grid):
        self.grid = gpu_grid
        self.ctx = gpu_grid.ctx
        self.gather = ComputeProgram(self.ctx, "atlas_gather.comp", gpu_grid)
        self.candidates = ComputeProgram(self.ctx, "atlas_candidates.comp", gpu_grid)
        self.fill = ComputeProgram(self.ctx, "atlas_fill.comp")
        self._variants = {
            shader: ComputeVariants(self.ctx, shader, gpu_grid)  # per case: _variant
            for shader in ("atlas_rays.comp", "atlas_bake.comp", "atlas_lookup.comp")
        }
        # The renderer's G-buffer
        self._drawn_lookup = DepthPickedDraw(self.ctx, "atlas_lookup.frag", gpu_grid)
        self.textures = TextureCache(self.ctx)
        self.texture = None  # rgba16f: r accessibility, g directional light, b probe light
        self.atom_slots = None  # int32 buffer: the patch of each atom (-1: culled, none)
        self.kept = None  # KeptCells of the patches' atoms
        self.slot_atoms = None  # uint32 buffer: the atom of each patch
        self.layout_key = self.ambient_key = self.sun_key = self.probe_key = None
        self.n_slots = self.patch = self.tiles_x = 0
        self.bake_seconds = 0.0  # the last bake's wall time (GPU drained)
        self.baked_patches = 0  # how many patches the last bake covered
        self.overflows = 0
        self._scratch: dict = {}  # the bake's storage by binding, kept for the next bake
        self._tables: tuple = (None, None)  # ((patch, directions), what _tables_for gives)
        self._fill_scratch = None  # rgba16f, the atlas's size: the fill's other texture

    # ------------------------------------------------------------ layout
    def _layout(self, patch: int) -> None:
        """Patches for the atoms the culling keeps, in rows of ceil(sqrt(n)) tiles."""
        key = (patch, self.grid.culling_version)
        if key == self.layout_key:
            return
        kept = np.flatnonzero(~self.grid.culled_mask).astype(np.uint32)
        n = max(int(kept.size), 1)
        tiles_x = math.ceil(math.sqrt(n))
        width, height = steady_side(tiles_x * patch), steady_side(math.ceil(n / tiles_x) * patch)
        limit = int(self.ctx.info.get("GL_MAX_TEXTURE_SIZE", 16384))
        if max(width, height) > limit or width * height * 4 > MAX_ATLAS_BYTES:
            raise ValueError(
                f"precomputed AO: {kept.size} patches of {patch}x{patch} texels need a "
                f"{width}x{height} atlas "
                f"(limit {limit} texels a side, {MAX_ATLAS_BYTES >> 20} MiB); "
                "use a smaller --ao-patch or a navigation cube"
            )
        self._release_layout()
        slots = np.full(self.grid.n_atoms, -1, dtype=np.int32)
        slots[kept] = np.arange(kept.size, dtype=np.int32)
        self.texture = self.ctx.texture((width, height), 4, dtype="f2")
        self.texture.repeat_x = self.texture.repeat_y = False
        self._fill_scratch = self.ctx.texture((width, height), 4, dtype="f2")
        self.slot_atoms = self.ctx.buffer(kept.tobytes() if kept.size else b"\0" * 4)
        self.atom_slots = self.ctx.buffer(slots.tobytes())
        self.kept = KeptCells(
            self.ctx,
            self.grid.grid.centers[kept],
            self.grid.vdw_radii[kept],
            self.grid.grid.cell_size,
        )
        self.n_slots, self.patch, self.tiles_x = int(kept.size), patch, tiles_x
        self.layout_key = key
        self.ambient_key = self.sun_key = self.probe_key = None

    # ------------------------------------------------------------ bake
    def update(
        self,
        patch: int,
        directions: int,
        distance: float,
        ambient: bool,
        sun_direction=None,
        probe_light: PointLight | None = None,
        progress=None,
    ) -> bool:
        """Bake what is missing: the accessibility (`ambient`) for (patch, directions,
        distance), the directional light's channel for `sun_direction` (towards the light)
        and the probe light's for `probe_light` (its position and range; only the patches of
        atoms within that range are baked); None: not wanted. Returns whether anything was
        baked; `progress(fraction)` is called per chunk."""
        self._layout(patch)
        want_ambient = ambient and self.ambient_key != (directions, float(distance))
        sun_key = (
            None
            if sun_direction is None
            else tuple(np.round(np.asarray(sun_direction, dtype=np.float64), 12))
        )
        want_sun = sun_key is not None and sun_key != self.sun_key
        probe_key = (
            None
            if probe_light is None
            else (tuple(probe_light.position), float(probe_light.radius))
        )
        want_probe = probe_key is not None and probe_key != self.probe_key
        if not (want_ambient or want_sun or want_probe):
            return False
        slots = np.arange(self.n_slots, dtype=np.uint32)
        if not (want_ambient or want_sun):  # the probe light alone: the atoms it reaches
            atoms = np.flatnonzero(self.slot_of() >= 0)
            near = (
                np.linalg.norm(self.grid.grid.centers[atoms] - probe_light.position, axis=1)
                <= probe_light.radius + self.grid.vdw_radii[atoms]
            )
            slots = np.sort(self.slot_of()[atoms[near]]).astype(np.uint32)
        t0 = time.perf_counter()
        self._bake(
            slots,
            directions,
            distance,
            want_ambient,
            sun_direction if want_sun else None,
            probe_light if want_probe else None,
            progress,
        )
        self.ctx.finish()
        self.bake_seconds = time.perf_counter() - t0
        self.baked_patches = int(slots.size)
        if want_ambient:
            self.ambient_key = (directions, float(distance))
        if want_sun:
            self.sun_key = sun_key
        if want_probe:
            self.probe_key = probe_key
        log.info(
            "occlusion atlas: %d of %d patches of %dx%d texels baked in %.2f s",
            slots.size,
            self.n_slots,
            patch,
            patch,
            self.bake_seconds,
        )
        return True

    def _bake(
        self,
        slots: np.ndarray,
        directions: int,
        distance: float,
        ambient: bool,
        sun_direction,
        probe_light,
        progress,
    ) -> None:
        grid = self.grid
        n = max(int(slots.size), 1)
        texel_words, direction_words = (
            math.ceil(self.patch * self.patch / 32),
            math.ceil(directions / 32),
        )
        # Bytes of each chunk-sized buffer per atom (the candidates and blocked bits: ambient
        # only).
        per_atom = {
            7: 4,
            18: texel_words * 4,
            9: directions * MASK_WORDS * 4 if ambient else 0,
            10: self.patch * self.patch * direction_words * 4 if ambient else 0,
        }
        image_bytes = (
            MAX_NEIGHBOURS + MAX_OVERLAPS
        ) * 16  # a row of the neighbours and overlaps images per atom
        most = max(1, min(CHUNK_SLOTS, MAX_SCRATCH_BYTES // (sum(per_atom.values()) + image_bytes)))
        chunk = math.ceil(n / math.ceil(n / most))  # chunks of equal size
        dirs, normals, facing, facing_directions = self._tables_for(directions)
        # the facing bits: only the accessibility's steps read them
        tables = (
            {BINDING_FACING_MASKS: facing, BINDING_FACING_DIRECTIONS: facing_directions}
            if ambient
            else {}
        )
        sizes = {
            **{binding: chunk * nbytes for binding, nbytes in per_atom.items()},
            11: 4,
            12: max(slots.nbytes, 4),
        }
        buffers = {binding: self._buffer(binding, nbytes) for binding, nbytes in sizes.items()}
        for binding, table in tables.items():
            buffers[binding] = self._buffer(binding, table.nbytes)
            buffers[binding].write(table.tobytes())
        images = {
            unit: self._chunk_image(unit, width, chunk)
            for unit, width in ((IMAGE_NEIGHBOURS, MAX_NEIGHBOURS), (IMAGE_OVERLAPS, MAX_OVERLAPS))
        }
        normals_block = self._buffer("texel normals", MAX_PATCH_TEXELS * 16)
        normals_block.write(normals.tobytes())
        directions_block = self._buffer("directions", MAX_DIRECTIONS * 16)
        directions_block.write(dirs.tobytes())
        buffers[11].write(np.zeros(1, dtype=np.uint32).tobytes())
        if slots.size:
            buffers[12].write(slots.tobytes())
        common = {
            **ray_epsilon_uniforms(),
            **light_uniforms(None, probe_light),
            "u_directions": directions,
            "u_distance": float(distance),
            "u_max_radius": float(np.max(grid.vdw_radii)) if grid.n_atoms else 0.0,
            "u_patch": self.patch,
            "u_tiles_x": self.tiles_x,
            "u_texel_words": texel_words,
            "u_direction_words": direction_words,
            "u_gather_neighbours": int(ambient),
            **self.kept.uniforms(),
        }
        if sun_direction is not None:
            d = np.asarray(sun_direction, dtype=np.float64)
            d = d / np.linalg.norm(d)
            common["u_sun_dir"] = tuple(float(v) for v in d)
            sun_buffer = grid.sun_buffer()  # the grid's: shared with the shadow pass
            sun_buffer.build(d, 0.0)  # hard: the patches hold hard shadows
            sun_buffer.bind()
            common.update(sun_buffer.uniforms())
        rays = self._variant("atlas_rays.comp", (("TWO_TEXEL_WORDS", texel_words <= 2),))
        bake = self._variant(
            "atlas_bake.comp",
            (
                ("BAKE_AMBIENT", ambient),
                ("BAKE_SUN", sun_direction is not None),
                ("BAKE_PROBE", probe_light is not None),
            ),
        )
        probe, reach = grid.probe_sphere, grid.probe_reach
        grid.set_probe(None)  # the atlas is the molecule's own
        try:
            self.slot_atoms.bind_to_storage_buffer(BINDING_SLOT_ATOMS)
            self.kept.bind()
            for binding, buffer in buffers.items():
                buffer.bind_to_storage_buffer(binding)
            normals_block.bind_to_uniform_block(BINDING_TEXEL_NORMALS)
            directions_block.bind_to_uniform_block(BINDING_DIRECTIONS)
            self.texture.bind_to_image(0, read=True, write=True)
            for unit, image in images.items():
                image.bind_to_image(unit, read=True, write=True)
            for first in range(0, int(slots.size), chunk):
                count = min(chunk, int(slots.size) - first)
                uniforms = {**common, "u_first_slot": first, "u_chunk_slots": count}
                # The overlaps: the hidden-texel test needs them
                self._dispatch(self.gather, count, uniforms)
                if ambient:  # a work group per atom
                    self._dispatch(self.candidates, count * LOCAL, uniforms)
                    self._dispatch(rays, count * LOCAL, uniforms)
                self._dispatch(bake, count * LOCAL, uniforms)
                if progress is not None:
                    progress((first + count) / slots.size)
            self.overflows = int(np.frombuffer(buffers[11].read(), dtype=np.uint32)[0])
            self._fill_unseen()
        finally:
            grid.set_probe(None if probe[3] <= 0 else probe[:3], probe[3], reach)
        if self.overflows:
            log.warning(
                "occlusion atlas: %d neighbour lists were full; those texels may be too bright",
                self.overflows,
            )

    def _tables_for(self, directions: int) -> tuple:
        """The directions (clustered, vec4), the texel normals (w: the sum of n.d over the
        directions facing the texel) and the facing bits of this patch size
        (atlas_tables.facing_masks), computed once per (patch, directions)."""
        key = (self.patch, directions)
        if self._tables[0] != key:
            dirs = np.zeros((directions, 4), dtype=np.float32)
            dirs[:, :3] = clustered(fibonacci_directions(directions))
            normals = texel_normals(self.patch)
            by_direction, by_texel, normals[:, 3] = facing_masks(normals, dirs)
            self._tables = (key, (dirs, normals, by_direction, by_texel))
        return self._tables[1]

    def _buffer(self, key, nbytes: int):
        """The bake's storage for `key` (its binding), at least `nbytes` (made again only to
        grow)."""
        buffer = self._scratch.get(key)
        if buffer is None or buffer.size < nbytes:
            if buffer is not None:
                buffer.release()
            buffer = self._scratch[key] = self.ctx.buffer(reserve=max(nbytes, 16))
        return buffer

    def _chunk_image(self, unit: int, width: int, chunk: int):
        """The bake's image for image `unit`, a row of `width` spheres per atom of the chunk
        (rgba32f; made again only to grow)."""
        key = ("image", unit)
        image = self._scratch.get(key)
        if image is None or image.height < chunk:
            if image is not None:
                image.release()
            image = self._scratch[key] = self.ctx.texture(
                (width, steady_side(chunk)), 4, dtype="f4"
            )
        return image

    def _fill_unseen(self) -> None:
        """Hidden texels take their seen neighbours' mean (shaders/atlas_fill.comp)."""
        scratch = self._fill_scratch
        for last, (source, target) in enumerate(((self.texture, scratch), (scratch, self.texture))):
            source.bind_to_image(0, read=True, write=False)
            target.bind_to_image(1, read=False, write=True)
            self.fill.run(
                *self.texture.size,
                {"u_patch": self.patch, "u_tiles_x": self.tiles_x, "u_last": last},
            )

    def _variant(self, shader: str, cases: tuple[tuple[str, bool], ...]) -> ComputeProgram:
        """`shader` for these cases, and without clipping code when nothing is cut away."""
        return self._variants[shader].get(*cases, ("NO_CLIPPING", not self.grid.culling.clipping))

    def _dispatch(self, compute: ComputeProgram, invocations: int, uniforms: dict) -> None:
        self.slot_atoms.bind_to_storage_buffer(BINDING_SLOT_ATOMS)
        compute.grid.bind()
        apply_uniforms(compute.program, {**compute.grid.uniforms(), **uniforms})
        compute.program.run(group_x=(invocations + LOCAL - 1) // LOCAL)
        self.ctx.memory_barrier()

    # ------------------------------------------------------------ lookup
    def lookup(
        self,
        gbuffer: GBuffer,
        ambient: bool = True,
        sun_direction=None,
        probe_light: PointLight | None = None,
        rect=None,
    ):
        """(accessibility, directional light, probe light) textures (r32f) of every G-buffer
        pixel; each written only when wanted (`ambient`; a light when given, `sun_direction`
        towards it), the others keep what they hold. `rect` (x, y, width, height): only those
        pixels, the probe light's 1 elsewhere (what lies beyond its range reads)."""
        size = gbuffer.size
        want_ambient = ambient
        ambient, sun = self.textures.get("ambient", size), self.textures.get("sun", size)
        lamp = (
            self.textures.get("probe_light", size)
            if rect is None
            else self.textures.fill("probe_light", size, 1.0)
        )
        x, y, w, h = rect if rect is not None else (0, 0, *size)
        gbuffer.bind()
        self.texture.filter = (self.ctx.LINEAR, self.ctx.LINEAR)
        self.texture.use(location=3)
        self.atom_slots.bind_to_storage_buffer(BINDING_ATOM_SLOTS)
        ambient.bind_to_image(0, read=False, write=True)
        sun.bind_to_image(1, read=False, write=True)
        lamp.bind_to_image(2, read=False, write=True)
        writes = (
            ("WRITE_AMBIENT", want_ambient),
            ("WRITE_SUN", sun_direction is not None),
            ("WRITE_PROBE", probe_light is not None),
        )
        cases = (("WITH_PROBE", self.grid.probe_sphere[3] > 0), *writes)
        uniforms = {
            **ray_epsilon_uniforms(),
            **light_uniforms(None, probe_light),
            "u_sun_dir": tuple(
                float(v) for v in (sun_direction if sun_direction is not None else (0.0, 0.0, 1.0))
            ),
            "u_patch": self.patch,
            "u_tiles_x": self.tiles_x,
            "u_atlas_size": tuple(float(v) for v in self.texture.size),
        }
        if gbuffer.depth is not None:  # the renderer's: the surfaces look up, the background is 1
            clipping = ("NO_CLIPPING", not self.grid.culling.clipping)
            picks = [((("BACKGROUND_ONLY", True), *writes), "=="), ((*cases, clipping), ">")]
            self._drawn_lookup.run(None, gbuffer.depth, (x, y, w, h), picks, uniforms)
        else:
            self._variant("atlas_lookup.comp", cases).run(
                w, h, {**uniforms, "u_offset": (int(x), int(y))}
            )
        return ambient, sun, lamp

    def read(self) -> np.ndarray:
        """The atlas as (H, W, 4) float32 (row 0 = atlas row 0)."""
        data = np.frombuffer(self.texture.read(), dtype=np.float16).reshape(
            self.texture.height, self.texture.width, 4
        )
        return data.astype(np.float32)

    def slot_of(self) -> np.ndarray:
        return np.frombuffer(self.atom_slots.read(), dtype=np.int32).copy()

    def _release_layout(self) -> None:
        for obj in (self.texture, self._fill_scratch, self.atom_slots, self.slot_atoms, self.kept):
            if obj is not None:
                obj.release()
        self.texture = self._fill_scratch = self.atom_slots = self.slot_atoms = self.kept = None

    def release(self) -> None:
        self._release_layout()
        self.textures.release()
        for buffer in self._scratch.values():
            buffer.release()
        for p in (
            self.gather,
            self.candidates,
            self.fill,
            self._drawn_lookup,
            *self._variants.values(),
        ):
            p.release()
