"""The lighting pass: shadows, ambient occlusion and edge cueing into the visibility buffer
before the shading pass. The probe light's shadow rays are the one term the shading pass
traces itself, per pixel, as it fetches the G-buffer anyway (shaders/shading_traced.frag);
path tracing (passes/path_trace.py) shares this pass's grid and lights.

Whole frames trace every term after the probe is drawn, the probe an occluder like any
atom. Layered frames (render/frame_planner.py) split the work at the probe:
MoleculeLightingPass computes the molecule's own terms before the probe is drawn, once per
molecule layer, and this pass then redoes only what the probe changes, over the plan's
regions; the shading pass takes in the probe's shadow of the sun and its share of the AO
per pixel (shaders/probe_share.glsl), so the visibility buffer keeps the molecule's terms
under the probe too. docs/rendering.md walks through both. Needs OpenGL 4.3.
"""

from __future__ import annotations

import logging
from dataclasses import replace

import numpy as np
from sasprobe.render.frame_planner import EVERYWHERE, LIT, LIT_BACKGROUND
from sasprobe.render.gl.compute import ComputeVariants
from sasprobe.render.gl.context import GLUnavailable
from sasprobe.render.gl.depth_picked import DepthPickedDraw
from sasprobe.render.gl.textures import TextureCache, read_texture
from sasprobe.render.lighting.ao import AmbientOcclusion
from sasprobe.render.lighting.ao.analytic import MAX_K
from sasprobe.render.lighting.culling import cube_culling
from sasprobe.render.lighting.edges import EdgeCueingProgram
from sasprobe.render.lighting.gbuffer import GBuffer
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
    light_uniforms,
    ray_epsilon_uniforms,
)
from sasprobe.render.lighting.shadows import ShadowTracer
from sasprobe.render.lighting.uploaded_grid import UploadedGrid
from sasprobe.render.passes.base import Frame, Pass, ProbeLighting, ProbeLightTrace
from sasprobe.render.rects import full_rect, grow_rect, intersect_rect, shadow_rect, union_rect

log = logging.getLogger("sasprobe")

REQUIRED_GL = 430
STILL_FRAMES = 3  # --shadows precomputed: frames the probe stands still before its light is baked
CYCLED_AO_MODES = tuple(m for m in AO_MODES if m != "off")
NO_NEIGHBOURS = np.full(MAX_K, -1, dtype=np.int32)
SHADOW_MARGIN = 0.05  # Å around the probe's shadow capsule
NO_PROBE_SHARE = {"u_probe_share_ambient": 0, "u_probe_share_sun": 0}  # shaders/probe_share.glsl
# This pass's own footprints (render/frame_planner.py)
EDGES, COMPOSE = "lighting edges", "lighting compose"


def lighting_supported(ctx) -> bool:
    return ctx.version_code >= REQUIRED_GL


class LightingPass(Pass):
    """The lighting's terms for the shading pass, on whole frames (`run`) and on layered ones
    (`run_molecule` before the probe is drawn, `run` after it)."""

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
                "shadows, ambient occlusion and path tracing need OpenGL 4.3 (compute shaders); "
                f"{ctx.info.get('GL_RENDERER', 'this driver')} offers "
                f"{ctx.info.get('GL_VERSION', ctx.version_code)}; use --shadows off --ao off"
            )
        self.ctx = ctx
        self.settings = settings
        self.shading = shading  # the shading pass's: probe attenuation, intensities
        self.layered = layered
        self.ao_mode = settings.ao.mode if settings.ao.mode != "off" else "analytic"
        # What follows the structure: the grid uploaded from the scene's, and what traces it.
        self.scene_grid = None  # the SceneState grid self.grid was uploaded from
        self.grid: UploadedGrid | None = None
        self.shadows = self.ao = self.tracer = self.compose = self.compose_drawn = None
        self.edges = EdgeCueingProgram(ctx)
        self.textures = TextureCache(ctx)
        self.lights: tuple[DirectionalLight | None, PointLight | None] = (None, None)
        # Keys of what the GPU state was last set for.
        self._culling_key: bytes | None = None
        self._probe_key: bytes | None = None
        self._still_key: tuple | None = None
        self._color_version: int | None = None  # the buffers' colours the path tracer has
        # The last frame's terms, as the G-buffer export reads them.
        self.exported_terms: dict[str, object] = {}
        # Layered frames: the molecule's own terms (kept with its layer), the atoms nearest
        # the probe by probe key, and the last compose's inputs (run again for the export).
        self.molecule_terms: dict[str, object] = {}
        self._probe_neighbours = (None, NO_NEIGHBOURS)
        self._composed = None
        # --shadows precomputed: frames the probe has stood still, and what one atlas lookup
        # gave along with the sun's: (frame index, accessibility, probe light).
        self._last_probe_key: bytes | None = None
        self._still_frames = 0
        self._looked_up = (-1, None, None)
        self._warned_shell = False
        # (light, soft) of the probe light the last frame's shading traced (for the export).
        self._untraced: tuple | None = None

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
        scene = frame.scene
        # A new structure, or the daemon changed the probe radius (the grid's expansion).
        if scene.grid is not self.scene_grid:
            self._release_structure()
            self.scene_grid = scene.grid
            self.grid = UploadedGrid(self.ctx, scene.grid, scene.structure.vdw_radii)
            self.shadows = ShadowTracer(self.grid)
            self.ao = AmbientOcclusion(self.grid, self.settings.ao)
            self.tracer = PathTracer.for_structure(self.grid, scene.structure)
            self.compose = ComputeVariants(self.ctx, "visibility_compose.comp", self.grid)
            self.compose_drawn = DepthPickedDraw(self.ctx, "visibility_compose.frag", self.grid)
            self._culling_key = self._probe_key = self._color_version = None
        if frame.buffers.color_version != self._color_version:  # the path tracer's albedos
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
        """Whether what the picture shows changed since the last frame (the path tracer
        restarts)."""
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

    def _sun(self, gbuffer: GBuffer, frame: Frame, sun: DirectionalLight, name: str):
        """The directional light's visibility: traced, or looked up in the occlusion atlas
        (--shadows precomputed, hard shadows only)."""
        if self._precomputed(frame):
            self._configure_ao()
            both = frame.scene.effects.ambient_occlusion and self.ao_mode == "precomputed"
            # A whole frame whose probe light comes from the atlas too looks all three up at once.
            lamp = (
                self.lights[1]
                if not frame.plan.layered and self._probe_light_baked(frame)
                else None
            )
            ambient, visibility, lit = self.ao.baked(
                gbuffer, ambient=both, sun_direction=sun.unit(), probe_light=lamp
            )
            self._looked_up = (frame.index, ambient if both else None, lit if lamp else None)
            return visibility
        area = frame.terms_rect()
        # 1 beyond the area: there the picture shows no atom
        out = (
            self.textures.fill(name, frame.size, 1.0)
            if area != full_rect(frame.size)
            else self.textures.get(name, frame.size)
        )
        return self.shadows.trace(gbuffer, sun, self._soft(frame), out=out, rect=area)

    def _precomputed(self, frame: Frame) -> bool:
        """Whether the lights' shadows come from the occlusion atlas (--shadows precomputed,
        hard shadows only)."""
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
        # None: no atom within the light's range.
        reach = frame.reach_rect(lamp.radius) or (0, 0, 0, 0)
        return self.ao.baked(gbuffer, ambient=False, probe_light=lamp, rect=reach)[2]

    def _probe_light_traced(self, frame: Frame, lamp: PointLight) -> ProbeLightTrace:
        """The probe light's shadow rays, for the shading pass to trace per pixel (it fetches
        the G-buffer anyway; a pass of their own would fetch it again). The export traces
        them into a texture of their own when it asks (exported_arrays)."""
        soft = self._soft(frame)
        self._untraced = (lamp, soft)
        return ProbeLightTrace(self.shadows, *self.shadows.prepared(lamp, soft))

    def _probe_light_baked(self, frame: Frame) -> bool:
        """Whether the probe light's shadows come from the atlas this frame."""
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
        drawn, area = frame.scene.sphere_selection(frame.camera), frame.terms_rect()
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
        the whole frame, drawn over the pixels a depth test picks (render/gl/depth_picked.py);
        with `export`, a layered frame's sun and ambient as the export gives them
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
        if frame.plan.layered:
            self._run_probe_layer(frame)
        else:
            self._run_whole(frame)

    def _run_whole(self, frame: Frame) -> None:
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
        self.exported_terms = {}
        if fx.shadows and sun is not None:
            self.exported_terms["shadow_dir"] = self._sun(gbuffer, frame, sun, "shadow_dir")
        traced = None
        if fx.shadows and lamp is not None:
            baked = self._baked_probe_light(frame, gbuffer, lamp)
            if baked is not None:
                self.exported_terms["shadow_probe"] = baked
            else:
                traced = self._probe_light_traced(frame, lamp)
        if fx.ambient_occlusion:
            self.exported_terms["ao"] = self._ambient(gbuffer, frame)
        terms = dict(self.exported_terms)
        if fx.edge_cueing:
            terms["edges"] = self._edges(gbuffer, frame)
        self._compose(frame, terms, {}, rect=frame.compose_rect())
        frame.probe_lighting = ProbeLighting(self.exported_terms.get("shadow_probe"), traced=traced)

    # ------------------------------------------------------------ layered frames
    def run_molecule(self, frame: Frame) -> None:
        """The molecule's own terms, on the molecule layer (no probe in the G-buffer or the
        grid): computed when the layer is drawn, and topped up with samples while it is kept."""
        self._sync(frame)
        self.grid.set_probe(None)
        fx = frame.scene.effects
        gbuffer = GBuffer.of_targets(frame.targets)
        if not frame.plan.molecule_kept:
            self.ao.view_changed()
            self.molecule_terms = {}
            sun = self.lights[0]
            if fx.shadows and sun is not None:
                self.molecule_terms["shadow_dir"] = self._sun(gbuffer, frame, sun, "molecule_sun")
            if fx.ambient_occlusion:
                self.molecule_terms["ao"] = self._ambient(gbuffer, frame)
        elif self._adding_samples(frame):
            self.molecule_terms["ao"] = self.ao.compute(
                gbuffer,
                frame.view,
                frame.proj,
                frame.scene.sphere_selection(frame.camera),
                frame.terms_rect(),
            )

    def _adding_samples(self, frame: Frame) -> bool:
        """Whether the molecule's AO takes more samples this frame (progressive AO on a kept
        layer)."""
        return (
            frame.scene.effects.ambient_occlusion and self.ao is not None and not self.ao.converged
        )

    def footprint(self, frame: Frame) -> dict:
        """Where the probe changes the picture this frame: its pixels, the edges around them
        and, on the atoms, where its shadow of the sun can fall; everywhere while the
        molecule's AO still takes samples (the molecule's terms then change everywhere)."""
        self._sync(frame)
        fx, size = frame.scene.effects, frame.size
        probe_rect = frame.probe_rect()
        touched, out = probe_rect, {}
        if fx.edge_cueing:
            out[EDGES] = grow_rect(probe_rect, self.settings.edge_settings().reach_px() + 1, size)
            touched = union_rect(touched, out[EDGES])
        if frame.plan.molecule_kept and self._adding_samples(frame):
            return {**out, COMPOSE: EVERYWHERE, LIT: EVERYWHERE, LIT_BACKGROUND: EVERYWHERE}
        sun = self.lights[0]
        shadow = None
        if fx.shadows and sun is not None and fx.probe and frame.scene.probe is not None:
            # it falls on the atoms drawn, nowhere else (the trace takes no shadow)
            shadow = intersect_rect(
                self._probe_shadow_rect(frame, sun, self._soft(frame)), frame.spheres_rect()
            )
        # the background shows the probe's pixels and the halos, not the sun's shadows; the
        # visibility buffer changes where the edges do
        return {
            **out,
            COMPOSE: out.get(EDGES),
            LIT: union_rect(touched, shadow),
            LIT_BACKGROUND: touched,
        }

    def _run_probe_layer(self, frame: Frame) -> None:
        """What the probe changes, after it is drawn, over the plan's regions."""
        fx, plan = frame.scene.effects, frame.plan
        probe_key = self._set_probe(frame)
        probe = self.grid.probe_sphere if probe_key else None
        self._stillness(frame, self._culling_key, probe_key)
        gbuffer = GBuffer.of_targets(frame.targets)
        sun, lamp = self.lights
        terms = dict(self.molecule_terms)
        self.exported_terms = {}
        soft = self._soft(frame)
        self._count_still_frames(probe_key)
        self._untraced = traced = None
        if fx.shadows and lamp is not None:
            baked = self._baked_probe_light(frame, gbuffer, lamp)
            if baked is not None:
                terms["shadow_probe"] = self.exported_terms["shadow_probe"] = baked
            else:  # traced by the shading pass, where it shades again
                traced = self._probe_light_traced(frame, lamp)
        if fx.edge_cueing:
            terms["edges"] = self._edges(gbuffer, frame, plan.region(EDGES))
        probe_ambient = fx.ambient_occlusion and probe is not None
        probe_sun = fx.shadows and sun is not None and probe is not None and "shadow_dir" in terms
        share = (
            {}
            if not (probe_ambient or probe_sun)
            else {
                **ray_epsilon_uniforms(),
                "u_probe_share_ambient": int(probe_ambient),
                "u_probe_share_sun": int(probe_sun),
                "u_share_probe": tuple(self.grid.probe_sphere),
                "u_share_probe_reach": self.grid.probe_reach,
                "u_share_sun_dir": light_uniforms(sun, None)["u_sun_dir"],
                "u_share_shell": soft.shell(),
                "u_share_shell_growth": float(soft.growth),
            }
        )
        # The visibility buffer holds the molecule's terms, under the probe too: the shading
        # pass colours the probe's own pixels without them, and takes the probe's share of
        # the atoms' light in itself. So it is composed where the molecule's terms or the
        # edges changed, and nowhere else.
        rect = intersect_rect(plan.region(COMPOSE), frame.compose_rect())
        if rect is not None:
            self._compose(frame, terms, {}, rect=rect)
        frame.probe_lighting = ProbeLighting(terms.get("shadow_probe"), share, traced)
        self._composed = (frame, terms, share, probe_key, probe_sun, probe_ambient)

    def _probe_shadow_rect(self, frame: Frame, sun, soft):
        """Pixels the probe's shadow of the sun can fall on (no drawn point lies beyond the
        molecule's bounding sphere), as wide as the probe with the soft shell's outer offset."""
        probe = frame.scene.probe
        reach = probe.radius + max(soft.outer, 0.0) + SHADOW_MARGIN
        bound = frame.scene.bounding_sphere(with_probe=False)
        return shadow_rect(probe.center, reach, -sun.unit(), bound, frame.viewproj, frame.size)

    def _neighbours(self, probe_key: bytes, probe) -> np.ndarray:
        """The atoms nearest the probe (the AO of its own pixels), found again when it moves."""
        if probe is None:
            return NO_NEIGHBOURS
        if self._probe_neighbours[0] != probe_key:
            self._probe_neighbours = (
                probe_key,
                self.grid.grid.nearest_to_point(probe[:3], MAX_K).astype(np.int32),
            )
        return self._probe_neighbours[1]

    # ------------------------------------------------------------ the G-buffer export
    def exported_arrays(self, frame: Frame) -> dict[str, np.ndarray]:
        """The last frame's lighting terms for the G-buffer export (row 0 = top) and the
        lights they were traced for."""
        if self._composed is not None:
            self._export_composed()
        if self._untraced is not None:  # the shading pass traced the probe light: trace it here
            lamp, soft = self._untraced
            self.exported_terms["shadow_probe"] = self.shadows.trace(
                GBuffer.of_targets(frame.targets),
                lamp,
                soft,
                out=self.textures.get("shadow_probe", frame.size),
            )
            self._untraced = None
        out = {
            name: read_texture(tex, top_first=True).astype(np.float32)
            for name, tex in self.exported_terms.items()
        }
        sun, lamp = self.lights
        if sun is not None:  # the way it travels, as --light gives it
            out["light_direction"] = -np.asarray(sun.direction, dtype=np.float64)
        if lamp is not None:
            out["probe_light"] = np.array([*lamp.position, lamp.radius], dtype=np.float64)
        return out

    def _export_composed(self) -> None:
        """The last layered frame's composed sun and ambient terms (the probe's share added,
        and the probe's own pixels' terms: its sun traced, its ambient the analytic
        occlusion of the atoms nearest it), written for the export."""
        frame, terms, share, probe_key, probe_sun, probe_ambient = self._composed
        sun, terms = self.lights[0], dict(terms)
        probe_rect = frame.probe_rect()
        if probe_sun and probe_rect is not None:
            terms["probe_pixels_sun"] = self.shadows.trace(
                GBuffer.of_targets(frame.targets),
                sun,
                self._soft(frame),
                out=self.textures.get("probe_pixels_sun", frame.size),
                rect=probe_rect,
                only_probe=True,
            )
        probe = self.grid.probe_sphere if probe_key else None
        uniforms = {
            **ray_epsilon_uniforms(),
            **light_uniforms(sun, None),
            **NO_PROBE_SHARE,
            **share,
            "u_probe_sun": int(probe_sun),
            "u_probe_ambient": int(probe_ambient),
            "u_k": int(self.settings.ao.k),
            "u_probe_neighbours": self._neighbours(probe_key, probe).tobytes(),
        }
        sun_out = self.textures.get("shadow_dir", frame.size)
        ao_out = self.textures.get("ao", frame.size)
        sun_out.bind_to_image(1, read=False, write=True)
        ao_out.bind_to_image(2, read=False, write=True)
        self._compose(frame, terms, uniforms, export=True)
        if "shadow_dir" in terms:
            self.exported_terms["shadow_dir"] = sun_out
        if frame.scene.effects.ambient_occlusion:
            self.exported_terms["ao"] = ao_out

    def _release_structure(self) -> None:
        parts = (self.shadows, self.ao, self.tracer, self.compose, self.compose_drawn, self.grid)
        for part in parts:
            if part is not None:
                part.release()

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
        return frame.plan.layered and self.lighting.enabled(frame)

    def run(self, frame: Frame) -> None:
        self.lighting.run_molecule(frame)
