"""What lies under the window's cursor: the last frame's G-buffer pixel, the surface point
there (the wheel zooms towards it), and where a picked atom's label goes."""

from __future__ import annotations

import numpy as np
from sasprobe.render.gl.targets import KIND_BACKGROUND

LABEL_OFFSET = (14.0, -10.0)  # the label's corner from the picked atom's centre on screen, pixels


def pixel_under(
    renderer, window_size: tuple[int, int], x: float, y: float
) -> tuple[int, int, np.ndarray] | None:
    """(atom id, kind, world position) of the last frame's G-buffer under a cursor position
    (window coordinates), or None before the first frame."""
    if renderer is None or renderer.last_frame is None:
        return None
    (ww, wh), (fw, fh) = window_size, renderer.targets.size
    return renderer.targets.read_pixel(x * fw / max(ww, 1), y * fh / max(wh, 1))


def point_under(renderer, camera, window_size: tuple[int, int], x: float, y: float) -> np.ndarray:
    """The surface point under the cursor, else the cursor's ray at the camera target's depth."""
    hit = pixel_under(renderer, window_size, x, y)
    if hit is not None and hit[1] != KIND_BACKGROUND:
        return hit[2]
    ww, wh = window_size
    ray = camera.ray((2.0 * x / max(ww, 1) - 1.0, 1.0 - 2.0 * y / max(wh, 1)), ww / max(wh, 1))
    forward = -camera.basis()[:, 2]
    return camera.eye + ray * (camera.distance / max(float(ray @ forward), 1e-6))


def label_position(
    viewproj: np.ndarray, centre: np.ndarray, size: tuple[int, int], label_size: tuple[int, int]
) -> tuple[float, float] | None:
    """Where a label beside a point goes (pixels from the top left, kept on screen), or None
    when the point is behind the camera."""
    clip = viewproj @ np.array([*centre, 1.0])
    if clip[3] <= 0:
        return None
    x = (clip[0] / clip[3] * 0.5 + 0.5) * size[0] + LABEL_OFFSET[0]
    y = (0.5 - clip[1] / clip[3] * 0.5) * size[1] + LABEL_OFFSET[1]
    w, h = label_size
    return min(max(x, 0.0), max(size[0] - w, 0.0)), min(max(y, 0.0), max(size[1] - h, 0.0))
