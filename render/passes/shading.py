"""Deferred shading: G-buffer + visibility buffer -> lit colour (shaders/shading.frag),
with the parameters of ShadingSettings (render/lighting/settings.py)."""

from __future__ import annotations

from sasprobe.render.gl.uniforms import apply_uniforms
from sasprobe.render.lighting.settings import ShadingSettings
from sasprobe.render.passes.base import Frame, Pass
from sasprobe.render.passes.probe import PROBE_COLOR


class ShadingPass(Pass):
    name = "shading"

    def __init__(self, ctx, programs, settings: ShadingSettings | None = None):
        self.settings = settings or ShadingSettings()
        self.prog = programs.get("fullscreen.vert", "shading.frag")
        self.vao = ctx.vertex_array(self.prog, [])
        for unit, name in enumerate(("u_albedo", "u_position", "u_normal", "u_ids", "u_visibility")):
            if name in self.prog:
                self.prog[name].value = unit

    def run(self, frame: Frame) -> None:
        ctx, t, scene, s = frame.ctx, frame.targets, frame.scene, self.settings
        fx = scene.effects
        for unit, tex in enumerate((t.albedo, t.position, t.normal, t.ids, t.visibility)):
            tex.use(unit)
        probe = scene.probe
        apply_uniforms(self.prog, {
            "u_eye": tuple(float(v) for v in frame.camera.eye),
            "u_background": s.background,
            "u_ambient": s.ambient,
            "u_ao_power": s.ao_power,
            "u_dir_enabled": int(fx.directional_light),
            "u_light_dir": tuple(float(v) for v in frame.light_direction),
            "u_dir_intensity": s.directional_intensity,
            "u_probe_light_enabled": int(fx.probe_light and probe is not None),
            "u_probe_center": tuple(float(v) for v in probe.center) if probe is not None else (0.0, 0.0, 0.0),
            "u_probe_intensity": s.probe_intensity,
            "u_probe_atten": s.probe_attenuation,
            "u_probe_range": s.probe_range,
            "u_shininess": s.shininess,
            "u_specular": s.specular,
            "u_touched_atom": int(probe.touched_atom) if (probe is not None and fx.highlight) else -1,
            "u_highlight": s.highlight,
            "u_probe_color": PROBE_COLOR,
        })
        t.lit_fbo.use()
        # No depth test, so no depth write: the cube wire later tests against the G-buffer depth.
        ctx.disable(ctx.DEPTH_TEST | ctx.BLEND)
        self.vao.render(ctx.TRIANGLES, vertices=3)

    def release(self) -> None:
        self.vao.release()
