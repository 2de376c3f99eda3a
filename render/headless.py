"""Headless rendering loop: N frames or S seconds through EGL, to PNG/MP4 and the G-buffer."""

from __future__ import annotations

import math
import statistics
import time
from dataclasses import dataclass, field
from typing import Callable

from sasprobe.render.camera import Camera
from sasprobe.render.gbuffer import gbuffer_arrays, save_gbuffer


@dataclass
class RunStats:
    frames: int = 0
    seconds: float = 0.0
    frame_times: list[float] = field(default_factory=list)

    @property
    def median_ms(self) -> float:
        return statistics.median(self.frame_times) * 1e3 if self.frame_times else float("nan")

    def summary(self) -> str:
        fps = self.frames / self.seconds if self.seconds > 0 else float("nan")
        return f"{self.frames} frame(s) in {self.seconds:.2f} s ({fps:.1f} fps, median frame {self.median_ms:.1f} ms)"


def run_headless(renderer, camera: Camera, frames: int | None, seconds: float | None, writer=None,
                 gbuffer_path=None, orbit_deg: float = 0.0, update: Callable[[], None] | None = None,
                 progress=None) -> RunStats:
    """Render until `frames` are done or `seconds` have passed (at least one frame).

    `orbit_deg` turns the camera that many degrees per frame about its up axis;
    `update` runs before each frame (e.g. to take the latest pose from the daemon).
    """
    stats = RunStats()
    step = math.radians(orbit_deg)
    axis = camera.up.copy()
    start = time.perf_counter()
    while True:
        if update is not None:
            update()
        t0 = time.perf_counter()
        renderer.render(camera)
        renderer.ctx.finish()
        stats.frame_times.append(time.perf_counter() - t0)
        stats.frames += 1
        if writer is not None:
            writer.write(renderer.read_image())
        if progress is not None:
            progress.update(1)
        elapsed = time.perf_counter() - start
        if frames is not None and stats.frames >= frames:
            break
        if frames is None and (seconds is None or elapsed >= seconds):
            break
        if step:
            camera.orbit(axis, step)
    stats.seconds = time.perf_counter() - start
    if gbuffer_path is not None:
        save_gbuffer(gbuffer_path, gbuffer_arrays(renderer))
    return stats


