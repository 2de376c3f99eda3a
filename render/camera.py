"""Perspective camera: framing, `--camera` specs, arcball rotate, zoom (to a point) and pan.

`Camera.framing` frames a set of spheres exactly: every sphere lies in the
view frustum narrowed to `fill` of the image, so the molecule spans that fraction of the
image's limiting side whatever its shape (`Camera.fitted` frames a bounding sphere, which
leaves a molecule that is not round small in the picture).

Matrices follow OpenGL conventions with column vectors (clip = proj @ view @ [x, y, z, 1]),
as numpy float64 arrays; `gl_bytes` gives the column-major float32 bytes a uniform wants.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass, field

import numpy as np
from sasprobe.protocol.view import DEFAULT_FOV, FIT_MARGIN

FIT_FILL = 0.9  # the framed spheres span this fraction of the image's limiting side


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
            right = np.cross(
                np.array([1.0, 0.0, 0.0]) if abs(back[0]) < 0.9 else np.array([0.0, 0.0, 1.0]), back
            )
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
    def fitted(
        cls,
        center: np.ndarray,
        radius: float,
        aspect: float,
        fov_y: float = DEFAULT_FOV,
        direction=(0.0, 0.0, 1.0),
        up=(0.0, 1.0, 0.0),
    ) -> Camera:
        """A camera on `direction` from the centre that shows the whole bounding sphere."""
        half = math.radians(fov_y) / 2.0
        half_x = math.atan(math.tan(half) * aspect)
        distance = max(float(radius), 1e-3) / math.sin(min(half, half_x)) * FIT_MARGIN
        center = np.asarray(center, dtype=np.float64)
        cam = cls(
            eye=center + _unit(np.asarray(direction, dtype=np.float64)) * distance,
            target=center,
            up=np.asarray(up, dtype=np.float64),
            fov_y=fov_y,
        )
        cam.fit_clip_range(center, radius)
        return cam

    @classmethod
    def framing(
        cls,
        centers,
        radii,
        aspect: float,
        fov_y: float = DEFAULT_FOV,
        direction=(0.0, 0.0, 1.0),
        up=(0.0, 1.0, 0.0),
        fill: float = FIT_FILL,
    ) -> Camera:
        """A camera looking from `direction` (from the spheres towards the eye) at the
        nearest distance where every sphere lies inside the frustum narrowed to `fill`:
        a sphere at view coordinates (x, y, z) (z towards the eye, relative to the target)
        is inside the side plane x = t·(D − z) of an eye at distance D when
        D ≥ z + (|x| + r·√(1 + t²)) / t, with t = fill·tan(half angle); likewise for y.
        The target is moved sideways so the spheres' projection is centred."""
        centers = np.asarray(centers, dtype=np.float64).reshape(-1, 3)
        radii = np.broadcast_to(np.asarray(radii, dtype=np.float64), centers.shape[:1])
        back = _unit(np.asarray(direction, dtype=np.float64))
        probe = cls(eye=back, target=np.zeros(3), up=np.asarray(up, dtype=np.float64), fov_y=fov_y)
        basis = probe.basis()  # right, up, back
        local = centers @ basis
        ty = float(fill) * math.tan(math.radians(fov_y) / 2.0)
        tx = ty * float(aspect)
        middle = ((local - radii[:, None]).min(axis=0) + (local + radii[:, None]).max(axis=0)) / 2.0
        for _ in range(3):  # centre the projection (perspective shifts it), then fit again
            rel = local - middle
            distance = float(
                max(
                    np.max(rel[:, 2] + (np.abs(rel[:, 0]) + radii * math.hypot(1.0, tx)) / tx),
                    np.max(rel[:, 2] + (np.abs(rel[:, 1]) + radii * math.hypot(1.0, ty)) / ty),
                )
            )
            depth = distance - rel[:, 2]
            for axis, t in ((0, tx), (1, ty)):
                lo = np.min((rel[:, axis] - radii * math.hypot(1.0, t)) / depth)
                hi = np.max((rel[:, axis] + radii * math.hypot(1.0, t)) / depth)
                # The angular centre, at the target's depth
                middle[axis] += (lo + hi) / 2.0 * distance
        rel = local - middle
        distance = float(
            max(
                np.max(rel[:, 2] + (np.abs(rel[:, 0]) + radii * math.hypot(1.0, tx)) / tx),
                np.max(rel[:, 2] + (np.abs(rel[:, 1]) + radii * math.hypot(1.0, ty)) / ty),
            )
        )
        target = basis @ middle
        cam = cls(
            eye=target + back * distance,
            target=target,
            up=np.asarray(up, dtype=np.float64),
            fov_y=fov_y,
        )
        span = (
            float(np.max(np.linalg.norm(centers - target, axis=1) + radii)) if centers.size else 1.0
        )
        cam.fit_clip_range(target, span)
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

    def zoom_towards(self, point, factor: float) -> None:
        """Zoom about a world point (the one under the cursor): eye and target move towards
        it (factor < 1) or away, so it stays where it is on the screen."""
        p = np.asarray(point, dtype=np.float64)
        self.eye = p + (self.eye - p) * float(factor)
        self.target = p + (self.target - p) * float(factor)

    def centre_on(self, point) -> None:
        """Look at a point from the same direction and distance."""
        shift = np.asarray(point, dtype=np.float64) - self.target
        self.eye = self.eye + shift
        self.target = self.target + shift

    def ray(self, ndc: tuple[float, float], aspect: float) -> np.ndarray:
        """Unit direction (world) of the ray from the eye through a point in NDC (y up)."""
        t = math.tan(math.radians(self.fov_y) / 2.0)
        return _unit(self.basis() @ np.array([ndc[0] * t * aspect, ndc[1] * t, -1.0]))

    def pan(self, dx_px: float, dy_px: float, viewport_height: int) -> None:
        """Slide eye and target so the picture follows the pointer (pixels, y down)."""
        per_px = (
            2.0 * self.distance * math.tan(math.radians(self.fov_y) / 2.0) / max(viewport_height, 1)
        )
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
_CAMERA_KEYS = {"eye": 3, "target": 3, "up": 3, "dir": 3, "fov": 1}


def parse_camera(text: str) -> dict:
    """Parse 'eye=X,Y,Z target=X,Y,Z up=X,Y,Z dir=X,Y,Z fov=DEG' (any subset, spaces or ';';
    `dir` is the direction from the target towards the eye, at the framing distance).

    Raises ValueError with one line. Missing keys are framed later.
    """
    spec: dict = {}
    parts = [p for p in re.split(r"[;\s]+", text.strip()) if p]
    if not parts:
        raise ValueError(
            "empty camera spec (expected e.g. 'eye=0,0,80 target=0,0,0 up=0,1,0 fov=40')"
        )
    for part in parts:
        key, sep, value = part.partition("=")
        key = key.lower()
        if not sep or key not in _CAMERA_KEYS:
            raise ValueError(
                f"'{part}' is not one of eye=X,Y,Z target=X,Y,Z up=X,Y,Z dir=X,Y,Z fov=DEG"
            )
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
    for key in ("up", "dir"):
        if key in spec and np.linalg.norm(spec[key]) == 0.0:
            raise ValueError(f"{key}=0,0,0 has no direction")
    if "eye" in spec and "dir" in spec:
        raise ValueError("give eye=X,Y,Z or dir=X,Y,Z, not both")
    view = None
    if "eye" in spec and "target" in spec:
        view = spec["target"] - spec["eye"]
        if np.linalg.norm(view) == 0.0:
            raise ValueError("eye and target are the same point")
    elif "dir" in spec:
        view = -spec["dir"]
    if view is not None and "up" in spec:
        if np.linalg.norm(np.cross(view, spec["up"])) < 1e-9 * np.linalg.norm(
            view
        ) * np.linalg.norm(spec["up"]):
            raise ValueError("up is parallel to the viewing direction")
    return spec


def camera_from_spec(spec: dict, centers, radii, aspect: float) -> Camera:
    """A camera from a parsed spec; what it leaves out is framed to the spheres (Camera.framing)."""
    fov = float(spec.get("fov", DEFAULT_FOV))
    up = spec.get("up", np.array([0.0, 1.0, 0.0]))
    if "eye" in spec:
        if "target" in spec:
            target = spec["target"]
        else:
            centers = np.asarray(centers, dtype=np.float64).reshape(-1, 3)
            target = (centers.min(axis=0) + centers.max(axis=0)) / 2.0
        return Camera(eye=spec["eye"], target=target, up=up, fov_y=fov)
    framed = Camera.framing(
        centers, radii, aspect, fov_y=fov, direction=spec.get("dir", (0.0, 0.0, 1.0)), up=up
    )
    if "target" not in spec:
        return framed
    return Camera(
        eye=spec["target"] + (framed.eye - framed.target), target=spec["target"], up=up, fov_y=fov
    )


def _view_up(direction: np.ndarray) -> tuple[float, float, float]:
    return (
        (0.0, 1.0, 0.0) if abs(direction[1]) < 0.9 * np.linalg.norm(direction) else (0.0, 0.0, 1.0)
    )


def fit_bounding_sphere(
    centers,
    radii,
    aspect: float,
    direction=(0.0, 0.0, 1.0),
    fov_y_deg: float = 30.0,
    fill: float = 1.0,
) -> tuple[np.ndarray, np.ndarray]:
    """(view, proj) showing the spheres' bounding sphere (whatever the view turns to) from
    `direction`; fill > 1 zooms in by that factor (the lighting tests' and benchmarks' views)."""
    centers = np.asarray(centers, dtype=np.float64)
    radii = np.asarray(radii, dtype=np.float64)
    middle = ((centers - radii[:, None]).min(axis=0) + (centers + radii[:, None]).max(axis=0)) / 2.0
    radius = float(np.max(np.linalg.norm(centers - middle, axis=1) + radii))
    direction = np.asarray(direction, dtype=np.float64)
    camera = Camera.fitted(
        middle, radius / fill, aspect, fov_y=fov_y_deg, direction=direction, up=_view_up(direction)
    )
    camera.fit_clip_range(middle, radius)
    return camera.view(), camera.projection(aspect)
