"""Deferred shading: G-buffer + visibility buffer -> lit colour (shaders/shading.glsl), with
ShadingSettings (render/lighting/settings.py) and what the lighting hands over about the
probe (Frame.probe_lighting): its light's visibility as a texture, or its shadow rays,
which this pass then traces itself (shaders/shading_traced.frag).

On layered frames the shaded picture is kept and the pass shades again only the plan's
regions. Its footprint is the probe's pixels, the touched atom and the atoms within the
probe light's range (beyond it the probe changes nothing: its light and its share of the AO
are windowed to 0), and of the background the probe's pixels. Surfaces and background are
two draws over the pixels a depth test picks (render/gl/depth_picked.py), so llvmpipe never
runs the surfaces' six fetches for a background pixel.
"""

from __future__ import annotations

from sasprobe.render.frame_planner import LIT, LIT_BACKGROUND
from sasprobe.render.gl.depth_picked import DepthTestedTarget
from sasprobe.render.gl.uniforms import apply_uniforms
from sasprobe.render.lighting.settings import ShadingSettings
from sasprobe.render.passes.base import Frame, Pass, ProbeLighting
from sasprobe.render.passes.probe import PROBE_COLOR
from sasprobe.render.rects import intersect_rect, sphere_rect, subtract_rect, union_rect

# Units 0..5
TEXTURES = (
    "u_albedo",
    "u_position",
    "u_normal",
    "u_ids",
    "u_visibility",
    "u_probe_visibility",
)
# Image units (shaders/shading.glsl)
GBUFFER_IMAGES = {
    0: "position",
    1: "normal",
    6: "visibility",
    7: "ids",
}


class ShadingPass(Pass):
    name = "shading"

    def __init__(self, ctx, programs, settings: ShadingSettings | None = None):
        self.settings = settings or ShadingSettings()
        self.ctx = ctx
        self.programs = programs
        self._vaos: dict[tuple[str, ...], object] = {}
        self._depth_tested = DepthTestedTarget(ctx)  # the target with the G-buffer's depth

    def _vao(self, lit: ProbeLighting | None, context: bool = False):
        """The surfaces' program for what the lighting hands over (shaders/shading.frag's
        variants, or shading_traced.frag's when the probe light is traced here), with
        `context` the one for the backbone trace alone, or with None the background's."""
        fragment = "shading.frag"
        if lit is None:
            defines = ("AT_FAR_PLANE", "BACKGROUND_ONLY")
        elif context:
            defines = ("AT_FAR_PLANE", "CONTEXT")
        else:
            defines = (
                ("AT_FAR_PLANE",)
                + (("PROBE_SHADOWED",) if lit.visibility is not None else ())
                + (("PROBE_SHARE",) if lit.share else ())
            )
            if lit.traced is not None:
                fragment = "shading_traced.frag"
                defines += tuple(name for name, on in lit.traced.cases if on)
        key = (fragment, defines)
        if key not in self._vaos:
            prog = self.programs.get("fullscreen.vert", fragment, defines=defines)
            for unit, name in enumerate(TEXTURES):
                if name in prog:
                    prog[name].value = unit
            self._vaos[key] = self.ctx.vertex_array(prog, [])
        return self._vaos[key]

    def run(self, frame: Frame) -> None:
        ctx, t, scene, s = frame.ctx, frame.targets, frame.scene, self.settings
        fx = scene.effects
        lit = frame.probe_lighting
        for unit, tex in enumerate(
            (t.albedo, t.position, t.normal, t.ids, t.visibility, lit.visibility)
        ):
            if tex is not None:
                tex.use(unit)
        probe = scene.probe
        vao, background = self._vao(lit), self._vao(None)
        apply_uniforms(background.program, {"u_background": s.background})
        traced = {}
        # Its buffers bound again: passes since the lighting bound others
        if lit.traced is not None:
            lit.traced.shadows.bind()
            for unit, tex in GBUFFER_IMAGES.items():  # shading_traced.frag reads these as images
                getattr(t, tex).bind_to_image(unit, read=True, write=False)
            traced = {**lit.traced.shadows.grid.uniforms(), **lit.traced.uniforms}
        uniforms = {
            "u_eye": tuple(float(v) for v in frame.camera.eye),
            "u_background": s.background,
            "u_ambient": s.ambient,
            "u_ao_power": s.ao_power,
            "u_dir_enabled": int(fx.directional_light),
            "u_light_dir": tuple(float(v) for v in frame.light_direction),
            "u_dir_intensity": s.directional_intensity,
            "u_probe_light_enabled": int(fx.probe_light and probe is not None),
            "u_probe_center": tuple(float(v) for v in probe.center)
            if probe is not None
            else (0.0, 0.0, 0.0),
            "u_probe_intensity": s.probe_intensity,
            "u_probe_atten": s.probe_attenuation,
            "u_probe_range": s.probe_range,
            "u_shininess": s.shininess,
            "u_specular": s.specular,
            "u_touched_atom": int(probe.touched_atom)
            if (probe is not None and fx.highlight)
            else -1,
            "u_highlight": s.highlight,
            "u_probe_color": PROBE_COLOR,
        }
        apply_uniforms(vao.program, {**traced, **lit.share, **uniforms})
        plan = frame.plan
        target = t.kept_picture("shaded") if plan.layered else t.lit_fbo
        # Beyond the atoms and the probe the surfaces are the trace: its own, light program.
        lighting_rect, surfaces = frame.lighting_rect(), plan.region(LIT)
        draws = [
            (plan.region(LIT_BACKGROUND), background, "=="),
            (intersect_rect(surfaces, lighting_rect), vao, ">"),
        ]
        if surfaces is not None:
            context = self._vao(lit, context=True)
            apply_uniforms(context.program, uniforms)
            draws += [(rect, context, ">") for rect in subtract_rect(surfaces, lighting_rect)]
        # The depth is tested, not written: the cube wire later tests against it.
        tested = self._depth_tested.framebuffer(target.color_attachments[0], t.depth)
        tested.use()
        for rect, program, depth_func in draws:
            if rect is not None:
                tested.scissor = rect
                self._depth_tested.draw(program, depth_func)
        tested.scissor = None
        if target is not t.lit_fbo:
            ctx.copy_framebuffer(t.lit_fbo, target)  # the later passes draw over a copy

    def footprint(self, frame: Frame) -> dict:
        """Where the probe changes the shaded picture: its pixels, the touched atom and the
        lit atoms within its light's range; of the background, its pixels."""
        scene, probe = frame.scene, frame.scene.probe
        reached = frame.probe_rect()
        if probe is not None:
            reached = union_rect(reached, frame.reach_rect(self.settings.probe_range))
            if 0 <= probe.touched_atom < scene.structure.n_atoms:
                atom = probe.touched_atom
                reached = union_rect(
                    reached,
                    sphere_rect(
                        scene.structure.positions[atom],
                        scene.structure.vdw_radii[atom],
                        frame.viewproj,
                        frame.size,
                    ),
                )
        return {LIT: reached, LIT_BACKGROUND: frame.probe_rect()}

    def release(self) -> None:
        for vao in self._vaos.values():
            vao.release()
        self._vaos.clear()
        self._depth_tested.release()
