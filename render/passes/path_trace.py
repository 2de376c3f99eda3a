"""Progressive path tracing (Easdon's Algorithm 2) in place of the shaded image, after the
shading pass; it uses the lighting pass's grid, lights and stillness (passes/lighting.py)."""

from __future__ import annotations

from dataclasses import replace
from typing import TYPE_CHECKING

from sasprobe.render.frame_planner import EVERYWHERE, OVERLAY
from sasprobe.render.gl.compute import ComputeProgram
from sasprobe.render.lighting.gbuffer import GBuffer
from sasprobe.render.passes.base import Frame, Pass

if TYPE_CHECKING:
    from sasprobe.render.passes.lighting import LightingPass


class PathTracePass(Pass):
    name = "path_trace"

    def __init__(self, ctx, lighting: LightingPass):
        self.ctx = ctx
        self.lighting = lighting
        self.output = ComputeProgram(ctx, "path_trace_output.comp")

    def enabled(self, frame: Frame) -> bool:
        return frame.scene.effects.path_tracing

    @property
    def samples(self) -> int:
        tracer = self.lighting.tracer
        return tracer.samples if tracer is not None else 0

    def run(self, frame: Frame) -> None:
        lighting, settings = self.lighting, self.lighting.settings
        tracer = lighting.tracer
        gbuffer = GBuffer.of_targets(frame.targets)
        sun, lamp = lighting.lights
        s = lighting.shading
        tracing = replace(
            settings.path_tracer, sky=(s.ambient,) * 3, background=tuple(s.background)
        )
        target = max(settings.samples, min(tracer.samples + tracing.spp, tracing.max_samples))
        while tracer.samples < target or tracer.accumulated is None:
            tracer.accumulate(gbuffer, frame.camera.eye, sun, lamp, tracing)
        radiance = tracer.accumulated
        gbuffer.bind()
        radiance.use(location=3)
        frame.targets.visibility.use(location=4)
        frame.targets.lit.bind_to_image(0, read=False, write=True)
        self.output.run(*frame.size, {})

    def footprint(self, frame: Frame) -> dict:
        # It replaces the lit picture, adding samples: every pixel may change
        return {OVERLAY: EVERYWHERE}

    def release(self) -> None:
        self.output.release()
