"""The lighting in the renderer's pass chain: shadows, ambient occlusion and edge cueing
fill the visibility buffer before the shading pass, and progressive path tracing replaces
the lit image after it (passes/path_trace.py, sharing this pass's grid, lights and
stillness). The probe light's shadow rays are the one term not handed over as a texture:
the lighting builds their light buffer and the shading pass traces them per pixel, as it
fetches the G-buffer anyway (shaders/shading_traced.frag; unless they come from the
occlusion atlas). Two ways of computing one picture:

- **whole frames** (a renderer without the frame planner, or a frame it draws whole:
  the camera or culling changing frame after frame, render/frame_planner.py): LightingPass,
  after the probe is drawn, traces every term on the G-buffer the probe is in, the probe
  an occluder of the directional light and of the ambient occlusion like any atom;

      clear -> spheres -> backbone -> probe -> lighting -> shading -> path_trace -> navcube -> fxaa

- **layered frames** (frames whose pictures the planner keeps): MoleculeLightingPass,
  before the probe is drawn, computes the molecule's own terms — its shadows of the
  directional light, its ambient occlusion — on the molecule layer, once per molecule
  key (progressive AO keeps adding samples while the key holds, whatever the probe
  does); LightingPass, after the probe pass, recomputes what the probe changes: the probe
  light's shadows within its range (traced by the shading pass where it shades again),
  edge cueing around the probe (composed into the visibility buffer over the plan's
  regions only, shaders/visibility_compose.frag), and hands the shading pass the
  probe's shadow of the directional light and its share of the ambient occlusion as one
  sphere, which it takes in per pixel (shaders/probe_share.glsl); its footprint says where
  the shadow can fall, which is shaded again. With hard or soft shadows and analytic AO the result is the
  whole frame's; the traced, screen-space and precomputed AO methods take the molecule's
  occlusion without the probe and the probe's share analytically.

      clear -> spheres -> backbone -> molecule_lighting -> probe -> lighting -> shading -> ...

The grid is the scene's own (SceneState.grid, expanded radii: the daemon's), uploaded
once per structure; clip planes, the navigation cube and the probe come from the frame.
Needs OpenGL 4.3 (compute shaders, storage buffers).
"""

from __future__ import annotations

import logging
from dataclasses import replace

import numpy as np
from sasprobe.render.gl.compute import ComputeVariants
from sasprobe.render.gl.context import GLUnavailable
from sasprobe.render.gl.depth_picked import DepthPickedPass
from sasprobe.render.gl.textures import TextureCache, read_texture
from sasprobe.render.lighting.ao import AmbientOcclusion
from sasprobe.render.lighting.edges import EdgeCueingPass
from sasprobe.render.lighting.gbuffer import GBuffer
from sasprobe.render.lighting.grid import GpuGrid, cube_culling
from sasprobe.render.lighting.path_tracer import PathTracer
from sasprobe.render.lighting.settings import (
    AO_MODES,
    DEFAULT_PROBE_RANGE,
    HARD_SHADOW,
    DirectionalLight,
    LightingSettings,
    PointLight,
    ShadingSettings,
    SoftShadow,
)
from sasprobe.render.lighting.shadows import ShadowPass
from sasprobe.render.passes.base import Frame, Pass, ProbeLighting, ProbeLightTrace
from sasprobe.render.passes.lighting_layers import NO_NEIGHBOURS, LayeredLighting
from sasprobe.render.rects import full_rect

log = logging.getLogger("sasprobe")

REQUIRED_GL = 430
STILL_FRAMES = 3  # --shadows precomputed: frames the probe stands still before its light is baked
CYCLED_AO_MODES = tuple(m for m in AO_MODES if m != "off")


def lighting_supported(ctx) -> bool:
    return ctx.version_code >= REQUIRED_GL


class LightingPass(LayeredLighting, Pass):
    """Whole frames here; layered frames in LayeredLighting (passes/lighting_layers.py)."""

    name = "lighting"

    def __init__(
        self,
        ctx,
        settings: LightingSettings,
        shading: ShadingSettings | None,
        layered: bool = False,
    ):
        if not lighting_supported(ctx):
            raise GLUnavailable(
                f"shadows, ambient occlusion and path tracing need OpenGL 4.3 (compute shaders); "
                f"{ctx.info.get('GL_RENDERER', 'this driver')} offers {ctx.info.get('GL_VERSION', ctx.version_code)}; "
                "use --shadows off --ao off"
            )
        self.ctx = ctx
        self.settings = settings
        self.shading = shading  # the shading pass's: probe attenuation, intensities
        self.layered = layered
        self.ao_mode = settings.ao.mode if settings.ao.mode != "off" else "analytic"
        self.scene_grid = None  # the SceneState grid self.grid was uploaded from
        self.grid: GpuGrid | None = None
        self.shadows = self.ao = self.tracer = self.compose = self.compose_drawn = None
        self.edges = EdgeCueingPass(ctx)
        self._culling_key: bytes | None = None
        self._probe_key: bytes | None = None
        self._still_key: tuple | None = None
        self._color_version: int | None = None  # the buffers' colours the path tracer has
        self.textures = TextureCache(ctx)
        self.layers: dict[
            str, object
        ] = {}  # textures of the last frame's terms (for the G-buffer export)
        self.lights: tuple[DirectionalLight | None, PointLight | None] = (None, None)
        self.molecule_terms: dict[
            str, object
        ] = {}  # layered: the molecule's own terms, kept with its layer
        self._probe_neighbours = (
            None,
            NO_NEIGHBOURS,
        )  # layered: (probe key, atoms nearest the probe)
        self._last_probe_key: bytes | None = None
        self._composed = (
            None  # layered: the last compose's inputs, run again for the G-buffer export
        )
        self._looked_up = (
            -1,
            None,
            None,
        )  # (frame index, accessibility, probe light) given with the sun's
        self._still_frames = 0  # frames the probe has stood still
        self._warned_shell = False
        self._untraced: tuple | None = (
            None  # (light, soft) of the probe light the last frame's shading traced
        )

    # ------------------------------------------------------------ state
    def state(self):
        return (self.settings, self.ao_mode, self.layered)

    def enabled(self, frame: Frame) -> bool:
        fx = frame.scene.effects
        return fx.shadows or fx.ambient_occlusion or fx.edge_cueing or fx.path_tracing

    def cycle_ao_mode(self) -> str:
        self.ao_mode = CYCLED_AO_MODES[
            (CYCLED_AO_MODES.index(self.ao_mode) + 1) % len(CYCLED_AO_MODES)
        ]
        return self.ao_mode

    def _sync(self, frame: Frame) -> bytes:
        """Follow the frame's structure (grid), culling and lights; returns the culling key."""
        scene, fx = frame.scene, frame.scene.effects
        if (
            scene.grid is not self.scene_grid
        ):  # a new structure, or the daemon changed the probe radius
            self._release_structure()
            self.scene_grid = scene.grid
            self.grid = GpuGrid(self.ctx, scene.grid, scene.structure.vdw_radii)
            self.shadows = ShadowPass(self.grid)
            self.ao = AmbientOcclusion(self.grid, self.settings.ao)
            self.tracer = PathTracer.for_structure(self.grid, scene.structure)
            self.compose = ComputeVariants(self.ctx, "visibility_compose.comp", self.grid)
            self.compose_drawn = DepthPickedPass(self.ctx, "visibility_compose.frag", self.grid)
            self._culling_key = self._probe_key = self._color_version = None
        if (
            frame.buffers.color_version != self._color_version
        ):  # a colour scheme: the path tracer's albedos
            if frame.buffers.color_version:
                self.tracer.set_colors(scene.structure.elements, frame.buffers.colors)
            self._color_version = frame.buffers.color_version
        cube = frame.cube
        culling_key = frame.planes.tobytes() + (b"" if cube is None else cube.key())
        if culling_key != self._culling_key:
            self.grid.set_culling(cube_culling(frame.planes, cube))
            self._culling_key = culling_key
        self.lights = self.frame_lights(frame)
        return culling_key

    def frame_lights(self, frame: Frame) -> tuple[DirectionalLight | None, PointLight | None]:
        """The frame's directional light and probe light (None where off)."""
        s, scene, fx = self.shading, frame.scene, frame.scene.effects
        sun = (
            DirectionalLight(tuple(-frame.light_direction), np.pi * s.directional_intensity)
            if fx.directional_light and s.directional_intensity > 0
            else None
        )
        lamp = (
            PointLight(
                tuple(scene.probe.center),
                s.probe_range,
                np.pi * s.probe_intensity,
                tuple(s.probe_attenuation),
            )
            if (fx.probe_light and scene.probe is not None)
            else None
        )
        return sun, lamp

    def _set_probe(self, frame: Frame) -> bytes:
        """The probe as the grid's occluder (or none); returns its key."""
        probe = frame.scene.probe if frame.scene.effects.probe else None
        self.grid.set_probe(
            None if probe is None else probe.center,
            0.0 if probe is None else probe.radius,
            self.probe_reach,
        )
        return b"" if probe is None else np.array([*probe.center, probe.radius]).tobytes()

    def _stillness(self, frame: Frame, culling_key: bytes, probe_key: bytes) -> bool:
        """Whether what the picture shows changed since the last frame (the path tracer restarts)."""
        still = (
            np.asarray(frame.view).tobytes(),
            np.asarray(frame.proj).tobytes(),
            tuple(frame.size),
            culling_key,
            probe_key,
            self.lights,
            self.ao_mode,
            frame.scene.effects.path_tracing,
        )
        changed = still != self._still_key
        self._still_key = still
        if changed:
            self.tracer.reset()
        return changed

    # ------------------------------------------------------------ terms
    @property
    def probe_reach(self) -> float:
        """Å: how far the probe changes the picture: its light's range, where its share of the
        AO is windowed to 0 too (shaders/occluders.glsl probe_occlusion)."""
        return self.shading.probe_range if self.shading is not None else DEFAULT_PROBE_RANGE

    def _soft(self, frame: Frame) -> SoftShadow:
        return self._soft_shell() if frame.scene.effects.soft_shadows else HARD_SHADOW

    def _sun(self, gbuffer: GBuffer, frame: Frame, sun: DirectionalLight, name: str):
        """The directional light's visibility: traced, or looked up in the occlusion atlas
        (--shadows precomputed, hard shadows only)."""
        if self._precomputed(frame):
            self._configure_ao()
            both = frame.scene.effects.ambient_occlusion and self.ao_mode == "precomputed"
            # A whole frame whose probe light comes from the atlas too looks all three up at once.
            lamp = (
                self.lights[1] if not frame.plan.keeps and self._probe_light_baked(frame) else None
            )
            ambient, visibility, lit = self.ao.baked(
                gbuffer, ambient=both, sun_direction=sun.unit(), probe_light=lamp
            )
            self._looked_up = (
                frame.index,
                ambient if both else None,
                lit if lamp is not None else None,
            )
            return visibility
        area = frame.lighting_area()
        out = (
            self.textures.fill(name, frame.size, 1.0)
            if area != full_rect(frame.size)
            else self.textures.get(name, frame.size)
        )  # 1 beyond the area: there the picture shows no atom
        return self.shadows.trace(gbuffer, sun, self._soft(frame), out=out, rect=area)

    def _precomputed(self, frame: Frame) -> bool:
        """Whether the lights' shadows come from the occlusion atlas (--shadows precomputed; hard only)."""
        return self.settings.shadows == "precomputed" and not frame.scene.effects.soft_shadows

    def _count_still_frames(self, probe_key) -> None:
        self._still_frames = self._still_frames + 1 if probe_key == self._last_probe_key else 0
        self._last_probe_key = probe_key

    def _baked_probe_light(self, frame: Frame, gbuffer: GBuffer, lamp):
        """With --shadows precomputed and the probe standing still STILL_FRAMES frames, the
        probe light's visibility from the atlas (its light is then fixed in the molecule
        frame, whatever the camera does); else None (traced per pixel)."""
        if not self._probe_light_baked(frame):
            return None
        if self._looked_up[0] == frame.index and self._looked_up[2] is not None:
            return self._looked_up[2]
        self._configure_ao()
        reach = frame.reach_rect(lamp.radius) or (0, 0, 0, 0)  # none: no molecule within its range
        return self.ao.baked(gbuffer, ambient=False, probe_light=lamp, rect=reach)[2]

    def _probe_light_traced(self, frame: Frame, lamp: PointLight) -> ProbeLightTrace:
        """The probe light's shadow rays, for the shading pass to trace per pixel (it fetches
        the G-buffer anyway; a pass of their own would fetch it again). The export traces
        them into a texture of their own when it asks (gbuffer_layers)."""
        soft = self._soft(frame)
        self._untraced = (lamp, soft)
        return ProbeLightTrace(self.shadows, *self.shadows.prepared(lamp, soft))

    def _probe_light_baked(self, frame: Frame) -> bool:
        """Whether the probe light's shadows come from the atlas this frame (_baked_probe_light)."""
        return (
            self._precomputed(frame)
            and self._still_frames >= STILL_FRAMES
            and frame.scene.effects.shadows
        )

    def _configure_ao(self) -> None:
        self.ao.configure(
            replace(
                self.settings.ao,
                mode=self.ao_mode,
                reference_total=max(self.settings.ao.reference_total, self.settings.samples),
            )
        )

    def _ambient(self, gbuffer: GBuffer, frame: Frame):
        """The AO method's texture, brought to `samples` per pixel where it is progressive."""
        if self._looked_up[0] == frame.index and self._looked_up[1] is not None:
            return self._looked_up[1]
        self._configure_ao()
        drawn, area = frame.scene.sphere_selection(frame.camera), frame.lighting_area()
        texture = self.ao.compute(gbuffer, frame.view, frame.proj, drawn, area)
        while self.ao.samples < self.settings.samples and not self.ao.converged:
            texture = self.ao.compute(gbuffer, frame.view, frame.proj, drawn, area)
        return texture

    def _edges(self, gbuffer: GBuffer, frame: Frame, rect=None):
        return self.edges.compute(
            gbuffer,
            frame.view,
            frame.proj,
            self.settings.edge_settings(),
            out=self.textures.get("edges", frame.size),
            rect=rect,
        )

    def _compose(
        self, frame: Frame, terms: dict, uniforms: dict, export: bool = False, rect=None
    ) -> None:
        """The visibility buffer from the terms (shaders/visibility_terms.glsl) over `rect` or
        the whole frame, drawn (render/gl/depth_picked.py: faster than a compute pass on
        llvmpipe); with `export`, a layered frame's sun and ambient as the export gives them
        (shaders/visibility_compose.comp), into the images bound at 1 and 2."""
        ones = self.textures.get("ones", frame.size, fill=1.0)
        for unit, name in ((3, "shadow_dir"), (5, "ao"), (6, "edges"), (7, "probe_pixels_sun")):
            terms.get(name, ones).use(location=unit)
        t = frame.targets
        GBuffer.of_targets(t).bind()
        rect = rect if rect is not None else (0, 0, *frame.size)
        if export:
            self.compose.get().run(
                rect[2], rect[3], {**uniforms, "u_offset": (int(rect[0]), int(rect[1]))}
            )
        else:
            self.compose_drawn.run(t.visibility, t.depth, rect, [((), "1")], uniforms)

    # ------------------------------------------------------------ whole frames
    def run(self, frame: Frame) -> None:
        if frame.plan.keeps:
            self._run_probe_layer(frame)
            return
        self._composed = None  # a whole frame: the export reads its terms as they are
        self._untraced = None
        culling_key = self._sync(frame)
        probe_key = self._set_probe(frame)
        if probe_key != self._probe_key:
            self.ao.update_probe()
            self._probe_key = probe_key
        if self._stillness(frame, culling_key, probe_key):
            self.ao.view_changed()
        self._count_still_frames(probe_key)
        fx = frame.scene.effects
        gbuffer = GBuffer.of_targets(frame.targets)
        sun, lamp = self.lights
        self.layers = {}
        if fx.shadows and sun is not None:
            self.layers["shadow_dir"] = self._sun(gbuffer, frame, sun, "shadow_dir")
        traced = None
        if fx.shadows and lamp is not None:
            baked = self._baked_probe_light(frame, gbuffer, lamp)
            if baked is not None:
                self.layers["shadow_probe"] = baked
            else:
                traced = self._probe_light_traced(frame, lamp)
        if fx.ambient_occlusion:
            self.layers["ao"] = self._ambient(gbuffer, frame)
        terms = dict(self.layers)
        if fx.edge_cueing:
            terms["edges"] = self._edges(gbuffer, frame)
        self._compose(frame, terms, {}, rect=frame.lighting_area(composed=True))
        frame.probe_lighting = ProbeLighting(self.layers.get("shadow_probe"), traced=traced)

    # ------------------------------------------------------------ helpers
    def _soft_shell(self) -> SoftShadow:
        """The soft-shadow shell, cut to the grid's expansion: a daemon may shrink the probe
        radius (the grid's expansion) below the shell the renderer started with."""
        soft, limit = self.settings.soft, self.grid.max_shell
        if soft.outer <= limit + 1e-9:
            return soft
        if not self._warned_shell:
            log.warning("soft-shadow shell cut to %.2f Å, the probe radius", limit)
            self._warned_shell = True
        return replace(soft, inner=min(soft.inner, limit), outer=limit)

    def gbuffer_layers(self, frame: Frame) -> dict[str, np.ndarray]:
        """The last frame's lighting terms for the G-buffer export (row 0 = top) and the
        lights they were traced for."""
        if self._composed is not None:
            self._export_composed()
        if self._untraced is not None:  # the shading pass traced the probe light: traced here too
            lamp, soft = self._untraced
            self.layers["shadow_probe"] = self.shadows.trace(
                GBuffer.of_targets(frame.targets),
                lamp,
                soft,
                out=self.textures.get("shadow_probe", frame.size),
            )
            self._untraced = None
        out = {
            name: read_texture(tex, top_first=True).astype(np.float32)
            for name, tex in self.layers.items()
        }
        sun, lamp = self.lights
        if sun is not None:
            out["light_direction"] = -np.asarray(
                sun.direction, dtype=np.float64
            )  # as it travels, like --light
        if lamp is not None:
            out["probe_light"] = np.array([*lamp.position, lamp.radius], dtype=np.float64)
        return out

    def _release_structure(self) -> None:
        for thing in (
            self.shadows,
            self.ao,
            self.tracer,
            self.compose,
            self.compose_drawn,
            self.grid,
        ):
            if thing is not None:
                thing.release()

    def release(self) -> None:
        self._release_structure()
        self.edges.release()
        self.textures.release()


class MoleculeLightingPass(Pass):
    """The layered lighting's first half, before the probe is drawn (LightingPass.run_molecule)."""

    name = "molecule_lighting"

    def __init__(self, lighting: LightingPass):
        self.lighting = lighting

    def state(self):
        return None  # the lighting pass's settings are keyed under it

    def enabled(self, frame: Frame) -> bool:
        return frame.plan.keeps and self.lighting.enabled(frame)

    def run(self, frame: Frame) -> None:
        self.lighting.run_molecule(frame)
