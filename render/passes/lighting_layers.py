"""The layered half of the lighting pass (render/passes/lighting.py): frames whose pictures
the frame planner keeps (render/frame_planner.py). `run_molecule` computes the molecule's
own terms on the molecule layer before the probe is drawn (when the plan draws the layer;
progressive AO keeps adding samples while it is kept); `_run_probe_layer` then recomputes
what the probe changes, over the plan's regions: the probe light's shadow rays, for the
shading pass to trace where it shades again (or, with --shadows precomputed and the probe
standing still, its baked visibility), the edges around it, the visibility buffer where
the molecule's terms or the edges changed (shaders/visibility_compose.frag: it keeps the
molecule's terms under the probe, whose own pixels the shading pass colours without
them), and, for the shading pass, the probe's share of the atoms' light — its shadow of
the sun and its analytic share of the AO (shaders/probe_share.glsl, per pixel). Its
footprint says where all that lies, the pixels the shadow can fall on among them. The
probe's own pixels' terms are computed for the G-buffer export alone (_export_composed).

LayeredLighting is a mixin of LightingPass and uses its state (grid, shadows, ao, lights,
textures, settings) and its helpers (_sync, _set_probe, _sun, _ambient, _edges, _compose,
_count_still_frames, _baked_probe_light, frame_lights).
"""

from __future__ import annotations

import numpy as np
from sasprobe.render.frame_planner import EVERYWHERE, LIT, LIT_BACKGROUND
from sasprobe.render.lighting.ao.analytic import MAX_K
from sasprobe.render.lighting.gbuffer import GBuffer
from sasprobe.render.lighting.settings import light_uniforms, ray_epsilon_uniforms
from sasprobe.render.passes.base import Frame, ProbeLighting
from sasprobe.render.rects import capsule_rect, grow_rect, intersect_rect, union_rect

NO_NEIGHBOURS = np.full(MAX_K, -1, dtype=np.int32)
SHADOW_MARGIN = 0.05  # Å around the probe's shadow capsule
NO_PROBE_SHARE = {"u_probe_share_ambient": 0, "u_probe_share_sun": 0}  # shaders/probe_share.glsl
# This pass's own footprints (render/frame_planner.py)
EDGES, COMPOSE = "lighting edges", "lighting compose"


class LayeredLighting:
    def run_molecule(self, frame: Frame) -> None:
        """The molecule's own terms, on the molecule layer (no probe in the G-buffer or the
        grid): computed when the layer is drawn, and topped up with samples while it is kept."""
        self._sync(frame)
        self.grid.set_probe(None)
        fx = frame.scene.effects
        gbuffer = GBuffer.of_targets(frame.targets)
        if not frame.plan.kept:
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
                frame.lighting_area(),
            )

    def _adding_samples(self, frame: Frame) -> bool:
        """Whether the molecule's AO takes more samples this frame (a kept layer's progressive AO)."""
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
        if frame.plan.kept and self._adding_samples(frame):
            return {**out, COMPOSE: EVERYWHERE, LIT: EVERYWHERE, LIT_BACKGROUND: EVERYWHERE}
        sun = self.lights[0]
        shadow = None
        if fx.shadows and sun is not None and fx.probe and frame.scene.probe is not None:
            # it falls on the atoms drawn, nowhere else (the trace takes no shadow)
            shadow = intersect_rect(
                self._probe_shadow_rect(frame, sun, self._soft(frame)), frame.lit_rect()
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
        fx, plan = frame.scene.effects, frame.plan
        probe_key = self._set_probe(frame)
        probe = self.grid.probe_sphere if probe_key else None
        self._stillness(frame, self._culling_key, probe_key)
        gbuffer = GBuffer.of_targets(frame.targets)
        sun, lamp = self.lights
        terms = dict(self.molecule_terms)
        self.layers = {}
        soft = self._soft(frame)
        self._count_still_frames(probe_key)
        self._untraced = traced = None
        if fx.shadows and lamp is not None:
            baked = self._baked_probe_light(frame, gbuffer, lamp)
            if baked is not None:
                terms["shadow_probe"] = self.layers["shadow_probe"] = baked
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
        rect = intersect_rect(plan.region(COMPOSE), frame.lighting_area(composed=True))
        if rect is not None:
            self._compose(frame, terms, {}, rect=rect)
        frame.probe_lighting = ProbeLighting(terms.get("shadow_probe"), share, traced)
        self._composed = (frame, terms, share, probe_key, probe_sun, probe_ambient)

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
        sun_out, ao_out = (
            self.textures.get("shadow_dir", frame.size),
            self.textures.get("ao", frame.size),
        )
        sun_out.bind_to_image(1, read=False, write=True)
        ao_out.bind_to_image(2, read=False, write=True)
        self._compose(frame, terms, uniforms, export=True)
        if "shadow_dir" in terms:
            self.layers["shadow_dir"] = sun_out
        if frame.scene.effects.ambient_occlusion:
            self.layers["ao"] = ao_out

    def _probe_shadow_rect(self, frame: Frame, sun, soft):
        """Pixels the probe's shadow of the sun can fall on: the capsule from the probe away
        from the light to where that line leaves the molecule's bounding sphere, as wide as
        the probe with the soft shell's outer offset (no drawn point lies beyond)."""
        probe = frame.scene.probe
        reach = probe.radius + max(soft.outer, 0.0) + SHADOW_MARGIN
        centre, radius = frame.scene.bounding_sphere(with_probe=False)
        away = -sun.unit()
        w = np.asarray(probe.center, dtype=np.float64) - centre
        along = float(w @ away)
        disc = along * along - float(w @ w) + (radius + reach) ** 2
        length = (
            max(np.sqrt(disc) - along, 0.0) if disc > 0 else 0.0
        )  # |w + s away| = radius + reach
        return capsule_rect(
            probe.center, probe.center + length * away, reach, frame.viewproj, frame.size
        )

    def _neighbours(self, probe_key: bytes, probe) -> np.ndarray:
        """The atoms nearest the probe (for the AO of its own pixels), found again when it moves."""
        if probe is None:
            return NO_NEIGHBOURS
        if self._probe_neighbours[0] != probe_key:
            self._probe_neighbours = (
                probe_key,
                self.grid.grid.nearest_to_point(probe[:3], MAX_K).astype(np.int32),
            )
        return self._probe_neighbours[1]
