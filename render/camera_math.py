"""A camera framing given spheres, as (view, proj) matrices: what the lighting tests and
benchmark need of render/camera.py's Camera."""

from __future__ import annotations

import numpy as np

from sasprobe.render.camera import Camera


def fit_camera(centers, radii, aspect: float, direction=(0.0, 0.0, 1.0), fov_y_deg: float = 30.0,
               fill: float = 1.0) -> tuple[np.ndarray, np.ndarray]:
    """(view, proj) looking at the spheres' bounding sphere from `direction` (from the
    centre towards the eye); fill > 1 zooms in by that factor."""
    centers = np.asarray(centers, dtype=np.float64)
    radii = np.asarray(radii, dtype=np.float64)
    lo = (centers - radii[:, None]).min(axis=0)
    hi = (centers + radii[:, None]).max(axis=0)
    middle = (lo + hi) / 2.0
    radius = float(np.max(np.linalg.norm(centers - middle, axis=1) + radii))
    direction = np.asarray(direction, dtype=np.float64)
    up = (0.0, 1.0, 0.0) if abs(direction[1]) < 0.9 * np.linalg.norm(direction) else (0.0, 0.0, 1.0)
    camera = Camera.fitted(middle, radius / fill, aspect, fov_y=fov_y_deg, direction=direction, up=up)
    camera.fit_clip_range(middle, radius)
    return camera.view(), camera.projection(aspect)
