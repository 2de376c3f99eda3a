"""The workspace mapping: device tip (mm) -> goal in the molecule (Å), every tick, with the
view's turn, rate-control drift and the clutch.

The device's usable workspace box (DeviceLimits, mm) holds an inscribed cube of half
edge `half_mm` (the smallest half size of the box), centred on the box centre. That
cube maps onto the navigation cube in the molecule frame (centre C, half edge H Å, axes
the columns of the view rotation R) with one isotropic scale s = H / half_mm Å per mm,
so shapes are not distorted:

    goal_A = C + s * R (tip_mm - workspace_centre_mm)

R is the workspace view's orientation (the device frame is the camera frame, as in
CHAI3D and OpenHaptics applications): the renderer looks along -R[:, 2] with R[:, 1]
up, so device x, y, z are screen right, up and toward the viewer; it starts as the
identity (device axes = molecule axes). Turning the view (`turn`) turns the cube about
the goal, so the probe does not move when the view turns: the molecule turns around it.

Rate-control drift: the outer `margin_fraction` of the cube (per axis) is a margin.
Where the tip is inside the margin along an axis, the cube centre moves along that
(device) axis at `drift_speed_mm_s` (device-frame equivalent, so it feels the same at
every zoom) times a smoothstep ramp that is 0 at the inner edge of the margin and 1 at
the cube face and beyond. The drift speed is a continuous function of the tip position,
so the goal moves continuously and drift causes no force jump. The centre stays within
the bounding box of the atom centres, so the molecule cannot be lost.

Clutch (indexing): while held, the goal stays where it was and the cube moves with the
hand instead (C = goal - s R (tip - centre)), so the arm can be brought back to the
middle of its workspace without moving the probe.

Where and how large the cube starts is start.py.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

MARGIN_FRACTION = 0.15  # outer part of the cube (per axis) where the cube drifts
DRIFT_SPEED_MM_S = 30.0  # drift speed at the cube face, device-frame equivalent
IDENTITY = (1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0)  # the view rotation at the start, rows
ROTATION_TOLERANCE = 1e-6  # how far from orthonormal (with determinant +1) a view rotation may be


def validate_rotation(value) -> tuple[float, ...]:
    """A view rotation (3 x 3, rows; device frame -> molecule frame) as 9 floats, made exactly
    orthonormal; ValueError (one line) for anything that is not a proper rotation."""
    try:
        m = np.asarray(value, dtype=np.float64).reshape(3, 3)
    except (TypeError, ValueError):
        raise ValueError(f"a view rotation must be 3 x 3 numbers, got {str(value)[:60]}") from None
    if not np.all(np.isfinite(m)):
        raise ValueError("a view rotation must be finite")
    if np.max(np.abs(m @ m.T - np.eye(3))) > ROTATION_TOLERANCE or np.linalg.det(m) <= 0:
        raise ValueError(
            "a view rotation must be orthonormal with determinant +1 (a turn, not a mirror or "
            "a scale)"
        )
    # the nearest rotation: round-off does not accumulate over many turns
    u, _, vt = np.linalg.svd(m)
    return tuple(float(v) for v in (u @ vt).reshape(9))


def _smoothstep(x: float) -> float:
    if x <= 0.0:
        return 0.0
    if x >= 1.0:
        return 1.0
    return x * x * (3.0 - 2.0 * x)


@dataclass
class WorkspaceMapping:
    """Device workspace (mm) <-> navigation cube (Å), with the drift state (cube centre).

    All members are plain Python floats: the mapping runs every control tick.
    Callers outside the haptic engine should treat it as read-only.
    """

    workspace_center_mm: tuple[float, float, float]
    half_mm: float  # half edge of the inscribed cube in the device frame
    cube_center: list[float]  # Å, molecule frame; moves when drifting
    cube_half_A: float
    bounds_lo_A: tuple[float, float, float]  # the cube centre stays in this box
    bounds_hi_A: tuple[float, float, float]
    margin_fraction: float = MARGIN_FRACTION
    drift_speed_mm_s: float = DRIFT_SPEED_MM_S
    rotation: tuple[float, ...] = IDENTITY  # device -> molecule, row-major (the view's orientation)

    def copy(self) -> WorkspaceMapping:
        return WorkspaceMapping(
            self.workspace_center_mm,
            self.half_mm,
            list(self.cube_center),
            self.cube_half_A,
            self.bounds_lo_A,
            self.bounds_hi_A,
            self.margin_fraction,
            self.drift_speed_mm_s,
            self.rotation,
        )

    # ---------------------------------------------------------------- mapping
    @property
    def scale_A_per_mm(self) -> float:
        return self.cube_half_A / self.half_mm

    @property
    def cube_center_A(self) -> np.ndarray:
        return np.array(self.cube_center)

    @property
    def rotation_matrix(self) -> np.ndarray:
        return np.array(self.rotation).reshape(3, 3)

    @property
    def core_half_mm(self) -> float:
        """Half edge of the drift-free core of the cube (device frame)."""
        return self.half_mm * (1.0 - self.margin_fraction)

    def to_molecule(self, x: float, y: float, z: float) -> tuple[float, float, float]:
        """Device point (mm) -> molecule point (Å)."""
        s = self.cube_half_A / self.half_mm
        wx, wy, wz = self.workspace_center_mm
        u, v, w = s * (x - wx), s * (y - wy), s * (z - wz)
        r = self.rotation
        cx, cy, cz = self.cube_center
        return (
            cx + r[0] * u + r[1] * v + r[2] * w,
            cy + r[3] * u + r[4] * v + r[5] * w,
            cz + r[6] * u + r[7] * v + r[8] * w,
        )

    def to_device(self, x: float, y: float, z: float) -> tuple[float, float, float]:
        """Molecule point (Å) -> device point (mm)."""
        inv = self.half_mm / self.cube_half_A
        wx, wy, wz = self.workspace_center_mm
        cx, cy, cz = self.cube_center
        u, v, w = x - cx, y - cy, z - cz
        r = self.rotation  # its transpose takes molecule directions to the device frame
        return (
            wx + inv * (r[0] * u + r[3] * v + r[6] * w),
            wy + inv * (r[1] * u + r[4] * v + r[7] * w),
            wz + inv * (r[2] * u + r[5] * v + r[8] * w),
        )

    def _anchor(self, goal: tuple[float, float, float], tip_mm) -> None:
        """Place the cube so that the tip maps onto `goal` (the goal does not jump)."""
        cx, cy, cz = self.cube_center
        gx, gy, gz = self.to_molecule(*tip_mm)
        self.cube_center = [cx + goal[0] - gx, cy + goal[1] - gy, cz + goal[2] - gz]

    # ------------------------------------------------------------------ drift
    def drift_velocity_mm_s(self, x: float, y: float, z: float) -> tuple[float, float, float]:
        """Drift velocity of the cube for a tip position (device frame and mm/s equivalent)."""
        margin = self.half_mm * self.margin_fraction
        inner = self.half_mm - margin
        wx, wy, wz = self.workspace_center_mm
        if abs(x - wx) <= inner and abs(y - wy) <= inner and abs(z - wz) <= inner:
            return 0.0, 0.0, 0.0  # the usual case: inside the drift-free core
        out = []
        for u in (
            x - self.workspace_center_mm[0],
            y - self.workspace_center_mm[1],
            z - self.workspace_center_mm[2],
        ):
            depth = abs(u) - inner
            if depth <= 0.0:
                out.append(0.0)
            else:
                out.append(math.copysign(self.drift_speed_mm_s * _smoothstep(depth / margin), u))
        return out[0], out[1], out[2]

    def advance(self, x: float, y: float, z: float, dt: float) -> bool:
        """Move the cube for a tip position over dt seconds; True when it moved (drifting)."""
        vx, vy, vz = self.drift_velocity_mm_s(x, y, z)
        if (vx == 0.0 and vy == 0.0 and vz == 0.0) or dt <= 0.0:
            return False
        step = self.cube_half_A / self.half_mm * dt
        r = self.rotation
        moved = False
        for axis in range(3):
            # along this molecule axis
            v = r[3 * axis] * vx + r[3 * axis + 1] * vy + r[3 * axis + 2] * vz
            old = self.cube_center[axis]
            new = old + v * step
            # Stop at the bounds, never snap back into them (a snap would be a goal jump).
            if v > 0.0:
                new = min(new, max(old, self.bounds_hi_A[axis]))
            elif v < 0.0:
                new = max(new, min(old, self.bounds_lo_A[axis]))
            moved |= new != old
            self.cube_center[axis] = new
        return moved

    def hold(self, goal: tuple[float, float, float], tip_mm) -> None:
        """Clutch held: the cube follows the hand so that the tip keeps mapping onto `goal`."""
        self._anchor(goal, tip_mm)

    def rescale(self, cube_half_A: float, tip_mm: tuple[float, float, float] | None = None) -> None:
        """Change the cube size, zooming about the tip so the goal does not jump."""
        goal = self.to_molecule(*tip_mm) if tip_mm is not None else None
        self.cube_half_A = float(cube_half_A)
        if goal is not None:
            self._anchor(goal, tip_mm)

    def turn(self, rotation, tip_mm: tuple[float, float, float] | None = None) -> None:
        """A new view rotation (validate_rotation's 9 floats), turning about the goal so it
        does not jump."""
        goal = self.to_molecule(*tip_mm) if tip_mm is not None else None
        self.rotation = tuple(rotation)
        if goal is not None:
            self._anchor(goal, tip_mm)

    def recentre(self, point_A) -> None:
        """Centre the cube on a molecule point (the probe)."""
        self.cube_center = [float(v) for v in point_A]
