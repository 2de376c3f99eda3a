"""The ambient-occlusion family behind one call: `AmbientOcclusion.compute` returns the
accessibility texture (r32f, 1 = unoccluded) the shading pass multiplies in, made by the
method `AOSettings.mode` selects:

    off          none (all 1)
    analytic     Quilez sphere occlusion, K nearest neighbours + probe: K terms per pixel
    ssao         screen-space, point or line sampling, bilateral blur: N depth taps per pixel
    rt           cosine rays through the grid, `rt_spp` per frame, accumulated while the view
                 is still, blurred while noisy
    hybrid       analytic × rt
    reference    rt with `reference_spp` per frame until `reference_total`
    precomputed  QuteMol's per-atom patches (ao/precomputed.py), baked once per structure and
                 culling: one lookup per pixel

Call `view_changed()` whenever the G-buffer's content changes (camera, molecule, culling,
probe): accumulation then restarts.
"""

from __future__ import annotations

import numpy as np
from sasprobe.render.gl.compute import ComputeProgram
from sasprobe.render.gl.textures import TextureCache
from sasprobe.render.lighting.ao.analytic import AnalyticAO
from sasprobe.render.lighting.ao.blur import BilateralBlur
from sasprobe.render.lighting.ao.precomputed import OcclusionAtlas
from sasprobe.render.lighting.ao.raytraced import RayTracedAO
from sasprobe.render.lighting.ao.ssao import SSAO
from sasprobe.render.lighting.gbuffer import GBuffer
from sasprobe.render.lighting.settings import AOSettings

DEFAULT_AO = AOSettings()
BLUR_BELOW_SPP = 16  # ray-traced AO is blurred until this many samples have accumulated


class AmbientOcclusion:
    def __init__(self, gpu_grid, settings: AOSettings = DEFAULT_AO):
        self.grid = gpu_grid
        self.ctx = gpu_grid.ctx
        self.settings = settings
        self._programs: dict[str, object] = {}
        self.textures = TextureCache(self.ctx)

    # ------------------------------------------------------------ state
    def configure(self, settings: AOSettings) -> None:
        if (settings.mode, settings.distance) != (self.settings.mode, self.settings.distance):
            self.view_changed()
        self.settings = settings

    def view_changed(self) -> None:
        if "rt" in self._programs:
            self._programs["rt"].reset()

    @property
    def samples(self) -> int:
        """Ray-traced samples per pixel accumulated so far (rt, hybrid, reference)."""
        return self._programs["rt"].samples if "rt" in self._programs else 0

    @property
    def converged(self) -> bool:
        """Nothing left to add while the view stays still."""
        s = self.settings
        if s.mode in ("rt", "hybrid", "reference"):
            return self.samples >= s.reference_total
        return True

    # ------------------------------------------------------------ programs
    def program(self, name: str):
        if name not in self._programs:
            make = {
                "analytic": lambda: AnalyticAO(self.grid),
                "rt": lambda: RayTracedAO(self.grid),
                "ssao": lambda: SSAO(self.ctx),
                "blur": lambda: BilateralBlur(self.ctx),
                "multiply": lambda: ComputeProgram(self.ctx, "multiply.comp"),
                "atlas": lambda: OcclusionAtlas(self.grid),
            }[name]
            self._programs[name] = make()
        return self._programs[name]

    def update_probe(self) -> None:
        """The probe moved (after UploadedGrid.set_probe)."""
        if "analytic" in self._programs:
            self._programs["analytic"].update_probe()
        self.view_changed()

    def compute(
        self,
        gbuffer: GBuffer,
        view: np.ndarray,
        proj: np.ndarray,
        atoms: np.ndarray | None = None,
        rect=None,
    ):
        """The accessibility texture; `atoms`: those the G-buffer can show (None: any; analytic
        AO finds neighbour lists for them); `rect`: analytic AO only there, 1 elsewhere (None:
        everywhere; the other methods compute every pixel)."""
        s = self.settings
        size = gbuffer.size
        if s.mode == "off":
            return self.textures.get("ones", size, fill=1.0)
        if s.mode == "analytic":
            return self._analytic(gbuffer, atoms, rect)
        if s.mode == "precomputed":
            return self.baked(gbuffer, ambient=True)[0]
        if s.mode == "ssao":
            ssao = self.program("ssao")
            raw = ssao.compute(
                gbuffer,
                view,
                proj,
                s,
                out=self.textures.get("ssao", ssao.output_size(gbuffer, s.ssao_half_resolution)),
            )
            if not (s.blur or s.ssao_half_resolution):
                return raw
            return self.program("blur").apply(
                gbuffer, view, proj, raw, out=self.textures.get("blurred", size)
            )
        if s.mode == "reference":
            return self._traced(gbuffer, s.reference_spp, blur=False, view=view, proj=proj)
        traced = self._traced(gbuffer, s.rt_spp, blur=s.blur, view=view, proj=proj)
        if s.mode == "rt":
            return traced
        analytic = self._analytic(gbuffer, atoms, rect)
        product = self.textures.get("hybrid", size)
        analytic.use(location=3)
        traced.use(location=4)
        product.bind_to_image(0, read=False, write=True)
        self.program("multiply").run(size[0], size[1], {})
        return product

    def baked(
        self,
        gbuffer: GBuffer,
        ambient: bool,
        sun_direction=None,
        probe_light=None,
        rect=None,
        progress=None,
    ):
        """(accessibility, directional light, probe light) from the occlusion atlas, baked
        first where it lacks the accessibility (`ambient`), the light `sun_direction`
        (towards it) or the `probe_light` (a PointLight); `rect` as OcclusionAtlas.lookup."""
        s, atlas = self.settings, self.program("atlas")
        atlas.update(
            s.patch, s.directions, s.distance, ambient, sun_direction, probe_light, progress
        )
        return atlas.lookup(gbuffer, ambient, sun_direction, probe_light, rect)

    def _analytic(self, gbuffer: GBuffer, atoms: np.ndarray | None, rect=None):
        analytic = self.program("analytic")
        if self.grid.probe_sphere[3] > 0 and analytic.probe_neighbours[0] < 0:
            analytic.update_probe()
        return analytic.compute(
            gbuffer,
            self.settings.k,
            out=self.textures.get("analytic", gbuffer.size),
            atoms=atoms,
            rect=rect,
        )

    def _traced(self, gbuffer: GBuffer, spp: int, blur: bool, view, proj):
        rt = self.program("rt")
        if rt.samples < self.settings.reference_total:
            rt.accumulate(
                gbuffer,
                min(spp, self.settings.reference_total - rt.samples),
                self.settings.distance,
            )
        if blur and rt.samples < BLUR_BELOW_SPP:
            return self.program("blur").apply(
                gbuffer, view, proj, rt.accumulated, out=self.textures.get("blurred", gbuffer.size)
            )
        return rt.accumulated

    def release(self) -> None:
        for p in self._programs.values():
            p.release()
        self.textures.release()
        self._programs.clear()
