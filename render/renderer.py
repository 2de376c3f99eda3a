"""The renderer: GL objects created once, and the pass chain run each frame.

    clear -> spheres -> backbone -> [molecule_lighting] -> probe -> [lighting] -> shading
          -> [path_trace] -> navcube -> probe_cues -> fxaa -> legend -> marks

The bracketed passes come with the lighting (install_lighting). Before the chain runs, the
atoms' colours follow the scene's colour scheme, rewritten in the sphere buffer only when
the scheme changes. With `frame_cache` (the default) the frame planner
(render/frame_planner.py) decides what each frame redraws, and the passes of a kept layer
(Pass.layer) do not run; without it every frame is drawn whole (the benchmarks' full
redraw).
"""

from __future__ import annotations

import logging
import time
from typing import TYPE_CHECKING

import numpy as np
from sasprobe.molecule.colors import chain_colors, scheme_colors
from sasprobe.render.camera import Camera
from sasprobe.render.frame_planner import FramePlan, FramePlanner
from sasprobe.render.gl.buffers import MoleculeBuffers
from sasprobe.render.gl.programs import ProgramCache
from sasprobe.render.gl.targets import RenderTargets
from sasprobe.render.gl.textures import read_image
from sasprobe.render.lighting.settings import LightingSettings, ShadingSettings
from sasprobe.render.passes.backbone import BackbonePass
from sasprobe.render.passes.base import Frame, Layer, Pass
from sasprobe.render.passes.clear import ClearPass
from sasprobe.render.passes.fxaa import FxaaPass
from sasprobe.render.passes.legend import LegendPass
from sasprobe.render.passes.marks import MarksPass
from sasprobe.render.passes.navcube import NavCubePass
from sasprobe.render.passes.probe import ProbePass
from sasprobe.render.passes.probe_cues import ProbeCuesPass
from sasprobe.render.passes.shading import ShadingPass
from sasprobe.render.passes.spheres import sphere_pass
from sasprobe.render.scene_state import SceneState

if TYPE_CHECKING:
    from sasprobe.render.passes.lighting import LightingPass

log = logging.getLogger("sasprobe")


class Renderer:
    def __init__(
        self,
        ctx,
        scene: SceneState,
        size: tuple[int, int],
        sphere_mode: str = "quad",
        backbone_always: bool = False,
        shading: ShadingSettings | None = None,
        frame_cache: bool = True,
        wait_for_areas: bool = True,
    ):
        self.ctx = ctx
        self.scene = scene
        self.programs = ProgramCache(ctx)
        self.buffers = MoleculeBuffers(ctx, scene.structure, chain_colors(scene.structure))
        # The sas scheme's areas: computed at once (headless), or in the background (a window
        # keeps the previous colours meanwhile).
        self.wait_for_areas = wait_for_areas
        # What the buffers hold: CPK, as sphere_records writes
        self._color_key: tuple | None = (
            "element",
            None,
        )
        self.targets = RenderTargets(ctx, size)
        self.sphere_pass = sphere_pass(ctx, self.programs, self.buffers, sphere_mode)
        self.planner = FramePlanner(ctx, self.programs) if frame_cache else None
        self.passes: list[Pass] = [
            ClearPass(ctx, self.programs),
            self.sphere_pass,
            BackbonePass(ctx, self.programs, self.buffers, show_always=backbone_always),
            ProbePass(ctx, self.programs, self.buffers),
            ShadingPass(ctx, self.programs, shading),
            NavCubePass(ctx, self.programs),
            ProbeCuesPass(ctx, self.programs),
            FxaaPass(ctx, self.programs),
            LegendPass(ctx, self.programs),
            MarksPass(ctx, self.programs),
        ]
        self.lighting: LightingPass | None = None  # install_lighting's
        self.frame_index = 0
        self.last_frame: Frame | None = None

    # ------------------------------------------------------------- chain
    def set_sphere_mode(self, mode: str) -> None:
        """Swap the atoms' G-buffer pass (quad impostors, point sprites or meshes)."""
        new = sphere_pass(self.ctx, self.programs, self.buffers, mode)
        i = self.passes.index(self.sphere_pass)
        self.sphere_pass.release()
        self.passes[i] = self.sphere_pass = new

    @property
    def sphere_mode(self) -> str:
        return self.sphere_pass.mode

    def pass_named(self, name: str) -> Pass:
        return next(p for p in self.passes if p.name == name)

    def insert_before(self, name: str, new_pass: Pass) -> None:
        self.passes.insert(self.passes.index(self.pass_named(name)), new_pass)

    def install_lighting(
        self, settings: LightingSettings, required: bool = True
    ) -> LightingPass | None:
        """Slot the lighting into the chain (layered with a frame planner). Without OpenGL 4.3:
        GLUnavailable when `required`, else a warning and no lighting."""
        from sasprobe.render.passes.lighting import (
            LightingPass,
            MoleculeLightingPass,
            lighting_supported,
        )
        from sasprobe.render.passes.path_trace import PathTracePass

        if not lighting_supported(self.ctx):
            if required:
                LightingPass(self.ctx, settings, None)  # raises the one-line error
            log.warning(
                "OpenGL 4.3 is not available: "
                "rendering without shadows, ambient occlusion and path tracing"
            )
            return None
        layered = self.planner is not None
        shading = self.pass_named("shading").settings
        self.lighting = LightingPass(self.ctx, settings, shading, layered=layered)
        if layered:
            self.insert_before("probe", MoleculeLightingPass(self.lighting))
        self.insert_before("shading", self.lighting)
        self.insert_before("navcube", PathTracePass(self.ctx, self.lighting))
        return self.lighting

    def resize(self, size: tuple[int, int]) -> None:
        size = (max(int(size[0]), 1), max(int(size[1]), 1))
        if size != self.targets.size:
            self.targets.release()
            self.targets = RenderTargets(self.ctx, size)

    # ------------------------------------------------------------- frames
    def render(self, camera: Camera, output_fbo=None, pass_times: dict | None = None) -> Frame:
        """Run the chain once; the image lands in `output_fbo` (default: targets.final).

        With `pass_times`, the GPU is drained (glFinish) after every pass and each pass's
        wall time is added under its name (for benchmarks; it serialises the pipeline)."""
        self.sync_colors()
        camera.fit_clip_range(*self._clip_sphere())
        w, h = self.targets.size
        frame = Frame(
            ctx=self.ctx,
            programs=self.programs,
            targets=self.targets,
            buffers=self.buffers,
            scene=self.scene,
            camera=camera,
            view=camera.view(),
            proj=camera.projection(w / h),
            planes=self.scene.active_planes(camera),
            context_planes=self.scene.active_planes(camera, probe_plane=False),
            cube=self.scene.active_cube(),
            output_fbo=output_fbo if output_fbo is not None else self.targets.final_fbo,
            light_direction=self.scene.world_light_direction(camera),
            index=self.frame_index,
            plan=FramePlan(size=(w, h)),
        )
        if self.planner is not None:
            self.planner.plan(frame, self.passes)  # sets frame.plan
        plan = frame.plan
        # The molecule layer is complete in the G-buffer before the first pass after its last
        # one: what the probe will cover is stashed there, for the next frame to put back.
        layer_end = (
            max(
                (
                    i
                    for i, p in enumerate(self.passes)
                    if p.layer in (Layer.MOLECULE, Layer.CONTEXT)
                ),
                default=-1,
            )
            + 1
        )
        for i, p in enumerate(self.passes):
            if i == layer_end and plan.layered:
                self.planner.stash_under_probe(frame)
            if (
                not p.enabled(frame)
                or (plan.molecule_kept and p.layer in (Layer.MOLECULE, Layer.CONTEXT))
                or (plan.context_kept and p.layer == Layer.CONTEXT)
            ):
                continue
            if pass_times is None:
                p.run(frame)
                continue
            self.ctx.finish()
            t0 = time.perf_counter()
            p.run(frame)
            self.ctx.finish()
            pass_times[p.name] = pass_times.get(p.name, 0.0) + time.perf_counter() - t0
        self.frame_index += 1
        self.last_frame = frame
        return frame

    def _clip_sphere(self) -> tuple[np.ndarray, float]:
        """The sphere the near and far planes hold: the molecule and cube with room for a
        probe on its SAS and a probe diameter beyond (so the clip range, and with it the
        molecule layer, stays put while the probe moves there), widened only when the probe
        leaves that room."""
        scene = self.scene
        center, radius = scene.bounding_sphere(with_probe=False)
        radius += 4.0 * scene.probe_radius
        if scene.probe is not None:
            radius = max(
                radius, float(np.linalg.norm(scene.probe.center - center)) + scene.probe.radius
            )
        return center, radius

    def sync_colors(self) -> None:
        """The atoms' colours of the scene's scheme (sas: once its areas are known)."""
        scene = self.scene
        scheme = scene.color_scheme()
        key = (scheme, scene.probe_radius if scheme == "sas" else None)
        if key == self._color_key:
            return
        areas = (
            scene.atom_areas.get(scene.grid, wait=self.wait_for_areas) if scheme == "sas" else None
        )
        if scheme == "sas" and areas is None:
            return  # still being computed: keep what is drawn
        self.buffers.set_colors(scheme_colors(scene.structure, scheme, areas))
        self._color_key = key

    @property
    def colors_pending(self) -> bool:
        """The sas scheme is chosen and its areas are still being computed."""
        return self.scene.color_scheme() == "sas" and self._color_key[0] != "sas"

    def read_image(self, frame: Frame | None = None) -> np.ndarray:
        """The final image of a frame as H x W x 3 uint8, row 0 = top."""
        frame = frame or self.last_frame
        return read_image(frame.output_fbo, self.targets.size)

    def release(self) -> None:
        for p in self.passes:
            p.release()
        if self.planner is not None:
            self.planner.release()
        self.targets.release()
        self.buffers.release()
        self.programs.release()
