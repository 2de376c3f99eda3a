"""The lighting in the renderer's pass chain: shadows, ambient occlusion and edge cueing
fill the visibility buffer before the shading pass (LightingPass), and progressive path
tracing replaces the lit image after it (passes/path_trace.py, sharing this pass's grid,
lights and stillness).

    clear -> spheres -> probe -> backbone -> lighting -> shading -> path_trace -> navcube -> fxaa

The grid is the scene's own (SceneState.grid, expanded radii: the daemon's), uploaded
once per structure; clip planes, the navigation cube and the probe come from the frame.
Progressive effects (ray-traced AO, path tracing) accumulate while the frame's camera,
culling, probe and lights stay the same, and start over when any of them changes.
Needs OpenGL 4.3 (compute shaders, storage buffers).
"""

from __future__ import annotations

import logging
from dataclasses import replace

import numpy as np

from sasprobe.render.lighting.ao import AmbientOcclusion
from sasprobe.render.gl.context import GLUnavailable
from sasprobe.render.lighting.edges import EdgeCueingPass
from sasprobe.render.lighting.grid import Culling, GpuGrid
from sasprobe.render.gl.compute import ComputePass
from sasprobe.render.gl.textures import TextureCache, read_texture
from sasprobe.render.lighting.gbuffer import GBuffer
from sasprobe.render.lighting.settings import (
    AO_MODES,
    HARD_SHADOW,
    DirectionalLight,
    LightingSettings,
    PointLight,
    ShadingSettings,
    SoftShadow,
)
from sasprobe.render.passes.base import Frame, Pass
from sasprobe.render.lighting.path_tracer import PathTracer
from sasprobe.render.lighting.shadows import ShadowPass

log = logging.getLogger("sasprobe")

REQUIRED_GL = 430
CYCLED_AO_MODES = tuple(m for m in AO_MODES if m != "off")


def lighting_supported(ctx) -> bool:
    return ctx.version_code >= REQUIRED_GL


class LightingPass(Pass):
    name = "lighting"

    def __init__(self, ctx, settings: LightingSettings, shading: ShadingSettings | None):
        if not lighting_supported(ctx):
            raise GLUnavailable(
                f"shadows, ambient occlusion and path tracing need OpenGL 4.3 (compute shaders); "
                f"{ctx.info.get('GL_RENDERER', 'this driver')} offers {ctx.info.get('GL_VERSION', ctx.version_code)}; "
                "use --shadows off --ao off"
            )
        self.ctx = ctx
        self.settings = settings
        self.shading = shading  # the shading pass's: probe attenuation, intensities
        self.ao_mode = settings.ao.mode if settings.ao.mode != "off" else "analytic"
        self.scene_grid = None  # the SceneState grid self.grid was uploaded from
        self.grid: GpuGrid | None = None
        self.shadows = self.ao = self.tracer = None
        self.edges = EdgeCueingPass(ctx)
        self.compose = ComputePass(ctx, "visibility_compose.comp")
        self._culling_key: bytes | None = None
        self._probe_key: bytes | None = None
        self._still_key: bytes | None = None
        self._color_version: int | None = None  # the buffers' colours the path tracer has
        self.textures = TextureCache(ctx)
        self.layers: dict[str, object] = {}  # textures of the last frame's terms (for the G-buffer export)
        self.lights: tuple[DirectionalLight | None, PointLight | None] = (None, None)
        self._warned_shell = False

    # ------------------------------------------------------------ state
    def enabled(self, frame: Frame) -> bool:
        fx = frame.scene.effects
        return fx.shadows or fx.ambient_occlusion or fx.edge_cueing or fx.path_tracing

    def cycle_ao_mode(self) -> str:
        self.ao_mode = CYCLED_AO_MODES[(CYCLED_AO_MODES.index(self.ao_mode) + 1) % len(CYCLED_AO_MODES)]
        return self.ao_mode

    def _sync(self, frame: Frame) -> None:
        """Follow the frame: the structure (grid), culling, probe, lights; restart
        accumulation when what the picture shows has changed."""
        scene, fx = frame.scene, frame.scene.effects
        if scene.grid is not self.scene_grid:  # a new structure, or the daemon changed the probe radius
            self._release_structure()
            self.scene_grid = scene.grid
            self.grid = GpuGrid(self.ctx, scene.grid, scene.structure.vdw_radii)
            self.shadows = ShadowPass(self.grid)
            self.ao = AmbientOcclusion(self.grid, self.settings.ao)
            self.tracer = PathTracer.for_structure(self.grid, scene.structure)
            self._culling_key = self._probe_key = self._color_version = None
        if frame.buffers.color_version != self._color_version:  # a colour scheme: the path tracer's albedos
            if frame.buffers.color_version:
                self.tracer.set_colors(scene.structure.elements, frame.buffers.colors)
            self._color_version = frame.buffers.color_version
        cube = frame.cube
        culling_key = frame.planes.tobytes() + (b"" if cube is None else cube.key())
        if culling_key != self._culling_key:
            self.grid.set_culling(cube_culling(frame.planes, cube))
            self._culling_key = culling_key
        probe = scene.probe if fx.probe else None
        probe_key = b"" if probe is None else np.array([*probe.center, probe.radius]).tobytes()
        if probe_key != self._probe_key:
            self.grid.set_probe(None if probe is None else probe.center, 0.0 if probe is None else probe.radius)
            self.ao.update_probe()
            self._probe_key = probe_key
        s = self.shading
        sun = DirectionalLight(tuple(-frame.light_direction), np.pi * s.directional_intensity) \
            if fx.directional_light and s.directional_intensity > 0 else None
        lamp = PointLight(tuple(scene.probe.center), s.probe_range, np.pi * s.probe_intensity,
                          tuple(s.probe_attenuation)) if (fx.probe_light and scene.probe is not None) else None
        self.lights = (sun, lamp)
        still = b"".join([
            np.asarray(frame.view).tobytes(), np.asarray(frame.proj).tobytes(), np.array(frame.size).tobytes(),
            culling_key, probe_key, repr((sun, lamp, self.ao_mode, fx.path_tracing)).encode(),
        ])
        if still != self._still_key:
            self.ao.view_changed()
            self.tracer.reset()
            self._still_key = still

    # ------------------------------------------------------------ frame
    def run(self, frame: Frame) -> None:
        self._sync(frame)
        fx, size = frame.scene.effects, frame.size
        gbuffer = GBuffer.of_targets(frame.targets)
        ones = self.textures.get("ones", size, fill=1.0)
        sun, lamp = self.lights
        self.layers = {}
        if fx.shadows:
            soft = self._soft_shell() if fx.soft_shadows else HARD_SHADOW
            for name, light in (("shadow_dir", sun), ("shadow_probe", lamp)):
                if light is not None:
                    self.layers[name] = self.shadows.trace(gbuffer, light, soft, out=self.textures.get(name, size))
        if fx.ambient_occlusion:
            self.ao.configure(replace(self.settings.ao, mode=self.ao_mode,
                                      reference_total=max(self.settings.ao.reference_total, self.settings.samples)))
            texture = self.ao.compute(gbuffer, frame.view, frame.proj)
            while self.ao.samples < self.settings.samples and not self.ao.converged:
                texture = self.ao.compute(gbuffer, frame.view, frame.proj)
            self.layers["ao"] = texture
        edges = ones
        if fx.edge_cueing:
            edges = self.edges.compute(gbuffer, frame.view, frame.proj, self.settings.edge_settings(),
                                       out=self.textures.get("edges", size))
        for unit, texture in enumerate((self.layers.get("shadow_dir", ones), self.layers.get("shadow_probe", ones),
                                        self.layers.get("ao", ones), edges), start=3):
            texture.use(location=unit)
        frame.targets.visibility.bind_to_image(0, read=False, write=True)
        self.compose.run(*size, {})

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
        out = {name: read_texture(tex, top_first=True).astype(np.float32) for name, tex in self.layers.items()}
        sun, lamp = self.lights
        if sun is not None:
            out["light_direction"] = -np.asarray(sun.direction, dtype=np.float64)  # as it travels, like --light
        if lamp is not None:
            out["probe_light"] = np.array([*lamp.position, lamp.radius], dtype=np.float64)
        return out

    def _release_structure(self) -> None:
        for thing in (self.shadows, self.ao, self.tracer, self.grid):
            if thing is not None:
                thing.release()

    def release(self) -> None:
        self._release_structure()
        self.edges.release()
        self.compose.release()
        self.textures.release()


def cube_culling(planes: np.ndarray, cube) -> Culling:
    """The lighting's culling for the frame's planes and cube: an axis-aligned cube as the
    grid's box (its walk range shrinks to the cube), a turned one as its six face planes."""
    if cube is None:
        return Culling(planes, None)
    if cube.axis_aligned:
        return Culling(planes, (cube.center, cube.half))
    return Culling(np.concatenate([planes.reshape(-1, 4), cube.planes()]), None)


def install_lighting(renderer, settings: LightingSettings, required: bool = True) -> LightingPass | None:
    """Slot the lighting into a renderer's chain. Without OpenGL 4.3: GLUnavailable when
    `required`, else a warning and no lighting."""
    if not lighting_supported(renderer.ctx):
        if required:
            LightingPass(renderer.ctx, settings, None)  # raises the one-line error
        log.warning("OpenGL 4.3 is not available: rendering without shadows, ambient occlusion and path tracing")
        return None
    from sasprobe.render.passes.path_trace import PathTracePass

    lighting = LightingPass(renderer.ctx, settings, renderer.pass_named("shading").settings)
    renderer.insert_before("shading", lighting)
    renderer.insert_before("navcube", PathTracePass(renderer.ctx, lighting))
    return lighting


def lighting_of(renderer) -> LightingPass | None:
    return next((p for p in renderer.passes if isinstance(p, LightingPass)), None)


def lighting_status(renderer) -> str:
    """One line for the window's readout: which lighting effects are on, and how far the
    progressive ones have got."""
    lighting = lighting_of(renderer)
    fx = renderer.scene.effects
    parts = []
    if fx.shadows:
        parts.append("soft shadows" if fx.soft_shadows else "hard shadows")
    if fx.ambient_occlusion:
        progressive = lighting.ao_mode in ("rt", "hybrid", "reference") and lighting.ao is not None
        parts.append(f"AO {lighting.ao_mode}" + (f" {lighting.ao.samples} spp" if progressive else ""))
    if fx.edge_cueing:
        parts.append("edges")
    if fx.path_tracing and lighting.tracer is not None:
        parts.append(f"path tracing {lighting.tracer.samples} spp")
    return "lighting: " + (", ".join(parts) if parts else "off")


def apply_preset(renderer, preset, background=None) -> None:
    """Switch a running renderer to a lighting preset (render/lighting/presets.py): its light
    intensities and background (`background` overrides it) and which effects are on."""
    shading = renderer.pass_named("shading").settings
    for key, value in vars(preset.shading(shading)).items():  # in place: the lighting pass shares it
        setattr(shading, key, value)
    if background is not None:
        shading.background = tuple(background)
    lighting = lighting_of(renderer)
    if lighting is None:
        return
    lighting.settings = replace(preset.lighting, samples=lighting.settings.samples)
    if preset.lighting.ao.mode != "off":
        lighting.ao_mode = preset.lighting.ao.mode
    for key, value in preset.lighting.effects().items():
        setattr(renderer.scene.effects, key, value)
