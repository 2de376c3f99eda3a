"""Progressive path tracing through the grid (shaders/path_trace.comp; Easdon 2013,
Algorithm 2): up to 3 bounces, direct sampling of the directional and the probe light at
every vertex, per-element materials, a sky for escaping rays; accumulates while the view
is still. Output: linear radiance (rgba32f)."""

from __future__ import annotations

import numpy as np
from sasprobe.render.lighting.gbuffer import GBuffer
from sasprobe.render.lighting.materials import PROBE_MATERIAL, atom_materials
from sasprobe.render.lighting.progressive import ProgressiveProgram
from sasprobe.render.lighting.settings import (
    DirectionalLight,
    PathTracing,
    PointLight,
    light_uniforms,
    ray_epsilon_uniforms,
)

DEFAULT_TRACING = PathTracing()
BINDING_MATERIALS = 5


class PathTracer(ProgressiveProgram):
    components = 4

    def __init__(self, gpu_grid, materials: np.ndarray, seed: int = 7):
        """`materials`: (n_atoms, 8) rows from materials.atom_materials."""
        super().__init__(gpu_grid, "path_trace.comp", seed)
        materials = np.ascontiguousarray(materials, dtype=np.float32)
        if materials.shape != (gpu_grid.n_atoms, 8):
            raise ValueError("one material row (8 floats) per atom is needed")
        self.materials = self.ctx.buffer(materials.tobytes())

    @classmethod
    def for_structure(cls, gpu_grid, structure) -> PathTracer:
        return cls(gpu_grid, atom_materials(structure.elements, structure.colors))

    def set_colors(self, elements: np.ndarray, colors: np.ndarray) -> None:
        """The atoms' albedos from new colours (a colour scheme); accumulation starts over."""
        self.materials.write(
            np.ascontiguousarray(atom_materials(elements, colors), dtype=np.float32).tobytes()
        )
        self.reset()

    def accumulate(
        self,
        gbuffer: GBuffer,
        eye,
        sun: DirectionalLight | None,
        probe_light: PointLight | None,
        settings: PathTracing = DEFAULT_TRACING,
    ):
        self.materials.bind_to_storage_buffer(BINDING_MATERIALS)
        return self.add_samples(
            gbuffer,
            settings.spp,
            {
                **ray_epsilon_uniforms(),
                **light_uniforms(sun, probe_light),
                "u_bounces": int(settings.bounces),
                "u_eye": tuple(float(v) for v in eye),
                "u_sky": tuple(float(v) for v in settings.sky),
                "u_background": tuple(float(v) for v in settings.background),
                "u_probe_albedo_specular": PROBE_MATERIAL[:4],
                "u_probe_exponent": PROBE_MATERIAL[4],
            },
        )

    def release(self) -> None:
        super().release()
        self.materials.release()
