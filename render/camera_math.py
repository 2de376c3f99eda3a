"""View and projection matrices (OpenGL conventions, column vectors, float64) for the
lighting passes, their tests and the lighting benchmark."""

from __future__ import annotations

import math

import numpy as np


def look_at(eye, target, up=(0.0, 1.0, 0.0)) -> np.ndarray:
    eye, target, up = (np.asarray(v, dtype=np.float64) for v in (eye, target, up))
    forward = target - eye
    forward /= np.linalg.norm(forward)
    side = np.cross(forward, up)
    if np.linalg.norm(side) < 1e-9:  # looking along `up`: any perpendicular will do
        side = np.cross(forward, [1.0, 0.0, 0.0] if abs(forward[0]) < 0.9 else [0.0, 0.0, 1.0])
    side /= np.linalg.norm(side)
    true_up = np.cross(side, forward)
    view = np.eye(4)
    view[0, :3], view[1, :3], view[2, :3] = side, true_up, -forward
    view[:3, 3] = -view[:3, :3] @ eye
    return view


def perspective(fov_y_deg: float, aspect: float, near: float, far: float) -> np.ndarray:
    f = 1.0 / math.tan(math.radians(fov_y_deg) / 2.0)
    proj = np.zeros((4, 4))
    proj[0, 0], proj[1, 1] = f / aspect, f
    proj[2, 2] = (far + near) / (near - far)
    proj[2, 3] = 2.0 * far * near / (near - far)
    proj[3, 2] = -1.0
    return proj


def fit_camera(centers, radii, aspect: float, direction=(0.0, 0.0, 1.0), fov_y_deg: float = 30.0,
               fill: float = 1.0) -> tuple[np.ndarray, np.ndarray]:
    """(view, proj) looking at the molecule's bounding sphere from `direction` (from the
    centre towards the eye) so that the sphere fills `fill` of the smaller screen extent."""
    centers = np.asarray(centers, dtype=np.float64)
    lo = (centers - radii[:, None]).min(axis=0)
    hi = (centers + radii[:, None]).max(axis=0)
    middle = (lo + hi) / 2.0
    radius = float(np.max(np.linalg.norm(centers - middle, axis=1) + radii))
    half_fov = math.radians(fov_y_deg) / 2.0
    if aspect < 1.0:
        half_fov = math.atan(math.tan(half_fov) * aspect)
    distance = radius / math.sin(half_fov) / fill
    direction = np.asarray(direction, dtype=np.float64)
    eye = middle + direction / np.linalg.norm(direction) * distance
    up = (0.0, 1.0, 0.0) if abs(direction[1]) < 0.9 * np.linalg.norm(direction) else (0.0, 0.0, 1.0)
    view = look_at(eye, middle, up)
    near = max(distance - radius * 1.05, distance * 1e-3)
    return view, perspective(fov_y_deg, aspect, near, distance + radius * 1.05)
