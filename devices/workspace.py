"""The device workspace and the navigation cube in the molecule: mapping and drift.

The device's usable workspace box (DeviceLimits, mm) holds an inscribed cube of half
edge `half_mm` (the smallest half size of the box), centred on the box centre. That
cube maps onto the navigation cube in the molecule frame (centre C, half edge H Å) with
one isotropic scale s = H / half_mm Å per mm and no rotation (device axes = molecule
axes), so shapes are not distorted:

    goal_A = C + s * (tip_mm - workspace_centre_mm)

Rate-control drift: the outer `margin_fraction` of the cube (per axis) is a margin.
Where the tip is inside the margin along an axis, the cube centre moves along that
axis at `drift_speed_mm_s` (device-frame equivalent, so it feels the same at every
zoom) times a smoothstep ramp that is 0 at the inner edge of the margin and 1 at the
cube face and beyond. The drift speed is a continuous function of the tip position,
so the goal moves continuously and drift causes no force jump: a stationary tip that
starts drifting only sees the goal accelerate from rest. The centre stays within the
bounding box of the atom centres, so the molecule cannot be lost.

The fitted cube (`cube_half_A=None`) holds the whole solvent accessible surface in
its drift-free core, so a freshly started session never drifts unless the user
reaches for the edge.

It lives with the devices, not in the daemon's haptics, because two layers need the
same mapping: the haptic engine maps the tip through it every tick, and the simulated
arm places its scripted hand on the molecule with the mapping a session starts with.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from sasprobe.devices.base import DeviceLimits
from sasprobe.molecule.probe import DEFAULT_PROBE_RADIUS

MARGIN_FRACTION = 0.15  # outer part of the cube (per axis) where the cube drifts
DRIFT_SPEED_MM_S = 30.0  # drift speed at the cube face, device-frame equivalent
MAX_CUBE_HALF_A = 10_000.0  # larger navigation cubes are a mistake, not a molecule
FIT_PADDING_A = 3.0  # room around the SAS inside the fitted cube's core (to hover, to approach)


def validate_cube_half(value: float | None) -> float | None:
    """None, or a finite positive cube half edge in Å; ValueError (one line) otherwise."""
    if value is None:
        return None
    value = float(value)
    if not math.isfinite(value) or value <= 0 or value > MAX_CUBE_HALF_A:
        raise ValueError(f"navigation cube half edge must be in (0, {MAX_CUBE_HALF_A:g}] Å, got {value:g}")
    return value


def validate_cube_center(value) -> tuple[float, float, float] | None:
    """None, or three finite coordinates in Å; ValueError (one line) otherwise."""
    if value is None:
        return None
    try:
        xyz = tuple(float(v) for v in np.asarray(value, dtype=np.float64).reshape(3))
    except (TypeError, ValueError):
        raise ValueError(f"navigation cube centre must be three numbers (Å), got {value!r}") from None
    if not all(math.isfinite(v) for v in xyz):
        raise ValueError(f"navigation cube centre must be finite, got {xyz}")
    return xyz  # type: ignore[return-value]


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

    # ----------------------------------------------------------- construction
    @classmethod
    def initial(
        cls,
        structure,
        limits: DeviceLimits,
        cube_half_A: float | None = None,
        probe_radius: float = DEFAULT_PROBE_RADIUS,
        cube_center_A=None,
    ) -> "WorkspaceMapping":
        """The mapping a session starts with (the daemon and the simulated arm share it).

        Centre: `cube_center_A`, else the centre of the SAS bounding box. Half edge:
        `cube_half_A`, else the cube whose drift-free core holds the whole SAS with
        FIT_PADDING_A to spare.
        """
        cube_half_A = validate_cube_half(cube_half_A)
        cube_center_A = validate_cube_center(cube_center_A)
        positions = np.asarray(structure.positions, dtype=np.float64)
        reach = float(np.max(structure.vdw_radii)) + float(probe_radius)
        lo = positions.min(axis=0) - reach
        hi = positions.max(axis=0) + reach
        center = (lo + hi) / 2.0 if cube_center_A is None else np.asarray(cube_center_A)
        if cube_half_A is None:
            extent = float(np.max(np.maximum(hi - center, center - lo)))
            cube_half_A = (extent + FIT_PADDING_A) / (1.0 - MARGIN_FRACTION)
        ws_lo = np.asarray(limits.workspace_min_mm, dtype=np.float64)
        ws_hi = np.asarray(limits.workspace_max_mm, dtype=np.float64)
        half_mm = float(np.min(ws_hi - ws_lo)) / 2.0
        if not half_mm > 0:
            raise ValueError("device workspace has no extent")
        return cls(
            workspace_center_mm=tuple(float(v) for v in (ws_lo + ws_hi) / 2.0),  # type: ignore[arg-type]
            half_mm=half_mm,
            cube_center=[float(v) for v in center],
            cube_half_A=float(cube_half_A),
            bounds_lo_A=tuple(float(v) for v in positions.min(axis=0)),  # type: ignore[arg-type]
            bounds_hi_A=tuple(float(v) for v in positions.max(axis=0)),  # type: ignore[arg-type]
        )

    def copy(self) -> "WorkspaceMapping":
        return WorkspaceMapping(
            self.workspace_center_mm,
            self.half_mm,
            list(self.cube_center),
            self.cube_half_A,
            self.bounds_lo_A,
            self.bounds_hi_A,
            self.margin_fraction,
            self.drift_speed_mm_s,
        )

    # ---------------------------------------------------------------- mapping
    @property
    def scale_A_per_mm(self) -> float:
        return self.cube_half_A / self.half_mm

    @property
    def cube_center_A(self) -> np.ndarray:
        return np.array(self.cube_center)

    @property
    def core_half_mm(self) -> float:
        """Half edge of the drift-free core of the cube (device frame)."""
        return self.half_mm * (1.0 - self.margin_fraction)

    def to_molecule(self, x: float, y: float, z: float) -> tuple[float, float, float]:
        """Device point (mm) -> molecule point (Å)."""
        s = self.cube_half_A / self.half_mm
        wx, wy, wz = self.workspace_center_mm
        cx, cy, cz = self.cube_center
        return cx + s * (x - wx), cy + s * (y - wy), cz + s * (z - wz)

    def to_device(self, x: float, y: float, z: float) -> tuple[float, float, float]:
        """Molecule point (Å) -> device point (mm)."""
        inv = self.half_mm / self.cube_half_A
        wx, wy, wz = self.workspace_center_mm
        cx, cy, cz = self.cube_center
        return wx + inv * (x - cx), wy + inv * (y - cy), wz + inv * (z - cz)

    # ------------------------------------------------------------------ drift
    def drift_velocity_mm_s(self, x: float, y: float, z: float) -> tuple[float, float, float]:
        """Drift velocity of the cube for a tip position (device-frame equivalent, mm/s)."""
        margin = self.half_mm * self.margin_fraction
        inner = self.half_mm - margin
        wx, wy, wz = self.workspace_center_mm
        if abs(x - wx) <= inner and abs(y - wy) <= inner and abs(z - wz) <= inner:
            return 0.0, 0.0, 0.0  # the usual case: inside the drift-free core
        out = []
        for u in (x - self.workspace_center_mm[0], y - self.workspace_center_mm[1], z - self.workspace_center_mm[2]):
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
        moved = False
        for axis, v in enumerate((vx, vy, vz)):
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

    def rescale(self, cube_half_A: float, tip_mm: tuple[float, float, float] | None = None) -> None:
        """Change the cube size, zooming about the tip so the goal does not jump."""
        if tip_mm is not None:
            goal = self.to_molecule(*tip_mm)
        self.cube_half_A = float(cube_half_A)
        if tip_mm is not None:
            s = self.cube_half_A / self.half_mm
            self.cube_center = [g - s * (t - w) for g, t, w in zip(goal, tip_mm, self.workspace_center_mm)]
