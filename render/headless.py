"""Headless rendering loop: N frames or S seconds through EGL, to PNG/MP4 and the G-buffer."""

from __future__ import annotations

import math
import signal
import statistics
import threading
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from sasprobe.render.camera import Camera
from sasprobe.render.gbuffer_export import gbuffer_arrays, save_gbuffer


@dataclass
class RunStats:
    frames: int = 0  # frames rendered
    seconds: float = 0.0
    frame_times: list[float] = field(default_factory=list)
    # Frames written to a paced video (a late frame fills every slot it covered)
    video_frames: int = 0
    interrupted: str | None = None  # "SIGINT" / "SIGTERM" when a signal ended the run early
    # Frame planner: frames that kept the molecule layer / drew it anew.
    molecule_layer: dict | None = None

    @property
    def median_ms(self) -> float:
        return statistics.median(self.frame_times) * 1e3 if self.frame_times else float("nan")

    @property
    def fps(self) -> float:
        return self.frames / self.seconds if self.seconds > 0 else float("nan")

    def summary(self) -> str:
        return (
            f"{self.frames} frame(s) in {self.seconds:.2f} s "
            f"({self.fps:.1f} fps, median frame {self.median_ms:.1f} ms)"
        )

    def as_dict(self) -> dict:
        return {
            "frames": self.frames,
            "seconds": self.seconds,
            "fps": self.fps if self.frames else None,
            "median_frame_ms": self.median_ms if self.frame_times else None,
            "video_frames": self.video_frames,
            "interrupted": self.interrupted,
            "molecule_layer": self.molecule_layer,
        }


@contextmanager
def stop_on_signals() -> Iterator[dict]:
    """SIGINT and SIGTERM end the loop after the current frame (so a video is finished
    properly) instead of killing it mid-write; yields {"signal": name or None}."""
    state: dict = {"signal": None}
    if threading.current_thread() is not threading.main_thread():
        yield state
        return

    def note(signum, frame) -> None:
        state["signal"] = signal.Signals(signum).name

    previous = {sig: signal.signal(sig, note) for sig in (signal.SIGINT, signal.SIGTERM)}
    try:
        yield state
    finally:
        for sig, handler in previous.items():
            signal.signal(sig, handler)


def run_headless(
    renderer,
    camera: Camera,
    frames: int | None,
    seconds: float | None,
    writer=None,
    gbuffer_path=None,
    orbit_deg: float = 0.0,
    update: Callable[[], object | None] | None = None,
    progress=None,
    pace_fps: float | None = None,
    gbuffer_dir: Path | None = None,
    annotate: Callable[[np.ndarray], np.ndarray] | None = None,
) -> RunStats:
    """Render until `frames` are done or `seconds` have passed (at least one frame).

    `orbit_deg` turns the camera that many degrees per frame about its up axis;
    `update` runs before each frame (e.g. to take the latest pose from the daemon); a
    renderer it returns is drawn with from then on (the daemon's next structure).
    `pace_fps` (a live source into a video) keeps the video in wall-clock time: slot k is
    due k/pace_fps after the first frame is ready (its set-up is not filmed as a still), a
    frame is rendered when its slot is due, and one that took longer is written once per slot
    it covered, so the video has exactly round(seconds * pace_fps) (or `frames`) frames.
    `annotate` draws over each written picture (the readout of a daemon's live state).
    `gbuffer_dir` gets every frame's G-buffer as gbuffer_0000.npz, ... (uncompressed: quick
    to write).
    """
    stats = RunStats()
    step = math.radians(orbit_deg)
    axis = camera.up.copy()
    slots = None
    if pace_fps:
        slots = frames if frames is not None else max(1, round((seconds or 0.0) * pace_fps))
    start = time.perf_counter()
    video_start = start  # a paced video's slot 0: when its first frame is ready
    with stop_on_signals() as stop:
        while stop["signal"] is None:
            if update is not None:
                renderer = update() or renderer
            t0 = time.perf_counter()
            renderer.render(camera)
            renderer.ctx.finish()
            stats.frame_times.append(time.perf_counter() - t0)
            if gbuffer_dir is not None:
                save_gbuffer(
                    Path(gbuffer_dir) / f"gbuffer_{stats.frames:04d}.npz",
                    gbuffer_arrays(renderer),
                    compress=False,
                )
            stats.frames += 1
            image = renderer.read_image() if writer is not None else None
            if image is not None and annotate is not None:
                image = annotate(image)
            if slots is not None:
                if stats.frames == 1:
                    video_start = time.perf_counter()  # a large structure's set-up is not filmed
                # Slots whose start has passed
                covered = int((time.perf_counter() - video_start) * pace_fps)
                n = min(max(1, covered - stats.video_frames), slots - stats.video_frames)
                for _ in range(n):
                    if image is not None:
                        writer.write(image)
                stats.video_frames += n
                if progress is not None:
                    progress.update(n)
                if stats.video_frames >= slots:
                    break
                wait = video_start + stats.video_frames / pace_fps - time.perf_counter()
                if wait > 0:
                    time.sleep(wait)
            else:
                if image is not None:
                    writer.write(image)
                if progress is not None:
                    progress.update(1)
                elapsed = time.perf_counter() - start
                if frames is not None and stats.frames >= frames:
                    break
                if frames is None and (seconds is None or elapsed >= seconds):
                    break
            if step:
                camera.orbit(axis, step)
        stats.interrupted = stop["signal"]
    stats.seconds = time.perf_counter() - start
    if renderer.planner is not None:
        stats.molecule_layer = renderer.planner.layer_counts()
    if gbuffer_path is not None:
        save_gbuffer(gbuffer_path, gbuffer_arrays(renderer))
    return stats
