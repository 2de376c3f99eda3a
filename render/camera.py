"""Perspective camera: auto-fit, `--camera` specs, arcball rotate, zoom and pan.

Matrices follow OpenGL conventions with column vectors (clip = proj @ view @ [x, y, z, 1]),
as numpy float64 arrays; `gl_bytes` gives the column-major float32 bytes a uniform wants.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass, field

import numpy as np

DEFAULT_FOV = 40.0  # degrees, vertical
FIT_MARGIN = 1.05  # a little air around the fitted bounding sphere


def _unit(v: np.ndarray) -> np.ndarray:
    n = float(np.linalg.norm(v))
    if not math.isfinite(n) or n == 0.0:
        raise ValueError("zero-length vector")
    return v / n


def gl_bytes(matrix: np.ndarray) -> bytes:
    """Column-major float32 bytes of a (column-vector) matrix, as GL uniforms expect."""
    return np.ascontiguousarray(np.asarray(matrix, dtype=np.float32).T).tobytes()


@dataclass
class Camera:
    eye: np.ndarray
    target: np.ndarray
    up: np.ndarray = field(default_factory=lambda: np.array([0.0, 1.0, 0.0]))
    fov_y: float = DEFAULT_FOV  # degrees
    near: float = 0.1
    far: float = 1000.0

    def __post_init__(self) -> None:
        self.eye = np.asarray(self.eye, dtype=np.float64).reshape(3).copy()
        self.target = np.asarray(self.target, dtype=np.float64).reshape(3).copy()
        self.up = np.asarray(self.up, dtype=np.float64).reshape(3).copy()

    # ------------------------------------------------------------ matrices
    def basis(self) -> np.ndarray:
        """3x3 with columns right, up, backward (world), i.e. the inverse view rotation."""
        back = _unit(self.eye - self.target)
        right = np.cross(self.up, back)
        if np.linalg.norm(right) < 1e-9:  # looking along `up`: pick any perpendicular
            right = np.cross(np.array([1.0, 0.0, 0.0]) if abs(back[0]) < 0.9 else np.array([0.0, 0.0, 1.0]), back)
        right = _unit(right)
        return np.stack([right, np.cross(back, right), back], axis=1)

    def view(self) -> np.ndarray:
        b = self.basis()
        m = np.eye(4)
        m[:3, :3] = b.T
        m[:3, 3] = -b.T @ self.eye
        return m

    def projection(self, aspect: float) -> np.ndarray:
        f = 1.0 / math.tan(math.radians(self.fov_y) / 2.0)
        n, fa = self.near, self.far
        m = np.zeros((4, 4))
        m[0, 0] = f / aspect
        m[1, 1] = f
        m[2, 2] = (fa + n) / (n - fa)
        m[2, 3] = 2.0 * fa * n / (n - fa)
        m[3, 2] = -1.0
        return m

    @property
    def distance(self) -> float:
        return float(np.linalg.norm(self.eye - self.target))

    def fit_clip_range(self, center: np.ndarray, radius: float) -> None:
        """Near and far planes that hold a bounding sphere (near stays positive inside it)."""
        d = float(np.linalg.norm(self.eye - np.asarray(center, dtype=np.float64)))
        radius = max(float(radius), 1e-3)
        self.near = max(d - radius, radius * 1e-3)
        self.far = max(d + radius, self.near * 2.0)

    # ------------------------------------------------------------ fitting
    @classmethod
    def fitted(cls, center: np.ndarray, radius: float, aspect: float, fov_y: float = DEFAULT_FOV,
               direction=(0.0, 0.0, 1.0), up=(0.0, 1.0, 0.0)) -> "Camera":
        """A camera on `direction` from the centre that shows the whole bounding sphere."""
        half = math.radians(fov_y) / 2.0
        half_x = math.atan(math.tan(half) * aspect)
        distance = max(float(radius), 1e-3) / math.sin(min(half, half_x)) * FIT_MARGIN
        center = np.asarray(center, dtype=np.float64)
        cam = cls(eye=center + _unit(np.asarray(direction, dtype=np.float64)) * distance,
                  target=center, up=np.asarray(up, dtype=np.float64), fov_y=fov_y)
        cam.fit_clip_range(center, radius)
        return cam

    # ------------------------------------------------------------ interaction
    def orbit(self, axis_world: np.ndarray, angle: float) -> None:
        """Rotate the eye (and up) about the target by `angle` radians around a world axis."""
        rot = rotation_matrix(axis_world, angle)
        self.eye = self.target + rot @ (self.eye - self.target)
        self.up = rot @ self.up

    def arcball(self, p0: tuple[float, float], p1: tuple[float, float]) -> None:
        """Shoemake arcball between two pointer positions in NDC ([-1, 1], y up):
        the molecule turns with the pointer, so the camera turns the other way."""
        a, b = _arcball_point(p0), _arcball_point(p1)
        axis_view = np.cross(a, b)
        s = float(np.linalg.norm(axis_view))
        if s < 1e-12:
            return
        angle = math.atan2(s, float(np.dot(a, b)))
        self.orbit(self.basis() @ (axis_view / s), -angle)

    def zoom(self, factor: float) -> None:
        """Move the eye towards (factor < 1) or away from the target."""
        self.eye = self.target + (self.eye - self.target) * float(factor)

    def pan(self, dx_px: float, dy_px: float, viewport_height: int) -> None:
        """Slide eye and target so the picture follows the pointer (pixels, y down)."""
        per_px = 2.0 * self.distance * math.tan(math.radians(self.fov_y) / 2.0) / max(viewport_height, 1)
        b = self.basis()
        shift = (-dx_px * b[:, 0] + dy_px * b[:, 1]) * per_px
        self.eye = self.eye + shift
        self.target = self.target + shift


def rotation_matrix(axis: np.ndarray, angle: float) -> np.ndarray:
    """Rodrigues rotation about a unit axis."""
    k = _unit(np.asarray(axis, dtype=np.float64))
    kx = np.array([[0.0, -k[2], k[1]], [k[2], 0.0, -k[0]], [-k[1], k[0], 0.0]])
    return np.eye(3) + math.sin(angle) * kx + (1.0 - math.cos(angle)) * (kx @ kx)


def _arcball_point(p: tuple[float, float]) -> np.ndarray:
    x, y = float(p[0]), float(p[1])
    r2 = x * x + y * y
    if r2 <= 1.0:
        return np.array([x, y, math.sqrt(1.0 - r2)])
    s = 1.0 / math.sqrt(r2)
    return np.array([x * s, y * s, 0.0])


# ---------------------------------------------------------------- --camera
_CAMERA_KEYS = {"eye": 3, "target": 3, "up": 3, "fov": 1}


def parse_camera(text: str) -> dict:
    """Parse 'eye=X,Y,Z target=X,Y,Z up=X,Y,Z fov=DEG' (any subset, spaces or ';').

    Raises ValueError with one line. Missing keys are auto-fitted later.
    """
    spec: dict = {}
    parts = [p for p in re.split(r"[;\s]+", text.strip()) if p]
    if not parts:
        raise ValueError("empty camera spec (expected e.g. 'eye=0,0,80 target=0,0,0 up=0,1,0 fov=40')")
    for part in parts:
        key, sep, value = part.partition("=")
        key = key.lower()
        if not sep or key not in _CAMERA_KEYS:
            raise ValueError(f"'{part}' is not one of eye=X,Y,Z target=X,Y,Z up=X,Y,Z fov=DEG")
        if key in spec:
            raise ValueError(f"'{key}' is given twice")
        try:
            numbers = [float(v) for v in value.split(",")]
        except ValueError:
            raise ValueError(f"'{part}': not numbers") from None
        if len(numbers) != _CAMERA_KEYS[key] or not all(math.isfinite(v) for v in numbers):
            raise ValueError(f"'{part}': expected {_CAMERA_KEYS[key]} finite number(s)")
        spec[key] = numbers[0] if key == "fov" else np.array(numbers)
    if "fov" in spec and not 1.0 <= spec["fov"] <= 170.0:
        raise ValueError(f"fov={spec['fov']:g} is outside 1..170 degrees")
    if "up" in spec and np.linalg.norm(spec["up"]) == 0.0:
        raise ValueError("up=0,0,0 has no direction")
    if "eye" in spec and "target" in spec:
        view = spec["target"] - spec["eye"]
        if np.linalg.norm(view) == 0.0:
            raise ValueError("eye and target are the same point")
        up = spec.get("up", np.array([0.0, 1.0, 0.0]))
        if np.linalg.norm(np.cross(view, up)) < 1e-9 * np.linalg.norm(view) * np.linalg.norm(up) and "up" in spec:
            raise ValueError("up is parallel to the viewing direction")
    return spec


def camera_from_spec(spec: dict, center: np.ndarray, radius: float, aspect: float) -> Camera:
    """A camera from a parsed spec; what it leaves out is fitted to the bounding sphere."""
    fov = float(spec.get("fov", DEFAULT_FOV))
    target = spec.get("target", np.asarray(center, dtype=np.float64))
    up = spec.get("up", np.array([0.0, 1.0, 0.0]))
    if "eye" in spec:
        cam = Camera(eye=spec["eye"], target=target, up=up, fov_y=fov)
    else:
        fitted = Camera.fitted(center, radius, aspect, fov_y=fov, up=up)
        cam = Camera(eye=target + (fitted.eye - fitted.target), target=target, up=up, fov_y=fov)
    cam.fit_clip_range(center, radius)
    return cam


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
