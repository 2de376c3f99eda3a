"""The device workspace and the navigation cube in the molecule: mapping, view, drift, clutch.

The device's usable workspace box (DeviceLimits, mm) holds an inscribed cube of half
edge `half_mm` (the smallest half size of the box), centred on the box centre. That
cube maps onto the navigation cube in the molecule frame (centre C, half edge H Å, axes
the columns of the view rotation R) with one isotropic scale s = H / half_mm Å per mm,
so shapes are not distorted:

    goal_A = C + s * R (tip_mm - workspace_centre_mm)

R is the workspace view's orientation (the device frame is the camera frame, as in
CHAI3D and OpenHaptics applications): the renderer looks along -R[:, 2] with R[:, 1]
up, so device x, y, z are screen right, up and toward the viewer; it starts as the
identity (device axes = molecule axes). Turning the view (`set_view`) turns the cube
about the goal, so the probe does not move when the view turns: the molecule turns
around it.

The default size (`cube_half_A=None`) gives the physical workspace a useful scale and
the cube context around it: DEFAULT_SCALE_A_PER_MM Å per mm of hand travel (a 14 Å half
edge on an Omni-class arm's 35 mm: the probe's 2.8 Å diameter is 7 mm of hand travel,
and on a large structure's surface the cube holds about 300 atoms, as the navigation
cube of the HaptiMOL thesis' GroEL figure does), but at most CONTEXT_FRACTION of the
molecule's smallest width, so that the cube is a window onto part of the molecule and
the rest shows around it as the backbone trace (crambin: 5.6 Å, a few residues, at
0.16 Å per mm). It starts on the top of the surface (devices/surface.py), sunk by
SITE_SINK of its half edge so that most of it holds the molecule and the rest is room to
hover. The fitted cube (`cube_half_A="fit"`, or any cube at least that large) holds the
whole solvent accessible surface in its drift-free core, centred on it.

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
DEFAULT_SCALE_A_PER_MM = 0.4  # the default cube: this many Å per mm of hand travel ...
CONTEXT_FRACTION = 0.2  # ... and a half edge at most this fraction of the molecule's smallest width
SITE_SINK = (
    0.25  # a zoomed-in cube's centre lies this fraction of its half edge below the surface site
)
CUBE_FIT = "fit"  # cube_half_A that fits the whole molecule
IDENTITY = (
    1.0,
    0.0,
    0.0,
    0.0,
    1.0,
    0.0,
    0.0,
    0.0,
    1.0,
)  # the view rotation at the start, row-major
ROTATION_TOLERANCE = 1e-6  # how far from orthonormal (with determinant +1) a view rotation may be


def validate_cube_half(value: float | str | None) -> float | str | None:
    """None (the default size), "fit", or a finite positive half edge in Å; ValueError (one line) otherwise."""
    if value is None or value == CUBE_FIT:
        return value
    if isinstance(value, str):
        raise ValueError(
            f"navigation cube half edge must be a number (Å) or '{CUBE_FIT}', got {value!r}"
        )
    value = float(value)
    if not math.isfinite(value) or value <= 0 or value > MAX_CUBE_HALF_A:
        raise ValueError(
            f"navigation cube half edge must be in (0, {MAX_CUBE_HALF_A:g}] Å, got {value:g}"
        )
    return value


def validate_cube_center(value) -> tuple[float, float, float] | None:
    """None, or three finite coordinates in Å; ValueError (one line) otherwise."""
    if value is None:
        return None
    try:
        xyz = tuple(float(v) for v in np.asarray(value, dtype=np.float64).reshape(3))
    except (TypeError, ValueError):
        raise ValueError(
            f"navigation cube centre must be three numbers (Å), got {value!r}"
        ) from None
    if not all(math.isfinite(v) for v in xyz):
        raise ValueError(f"navigation cube centre must be finite, got {xyz}")
    return xyz  # type: ignore[return-value]


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
            "a view rotation must be orthonormal with determinant +1 (a turn, not a mirror or a scale)"
        )
    u, _, vt = np.linalg.svd(
        m
    )  # the nearest rotation: round-off does not accumulate over many turns
    return tuple(float(v) for v in (u @ vt).reshape(9))


def _smoothstep(x: float) -> float:
    if x <= 0.0:
        return 0.0
    if x >= 1.0:
        return 1.0
    return x * x * (3.0 - 2.0 * x)


def _sas_box(structure, probe_radius: float) -> tuple[np.ndarray, np.ndarray]:
    positions = np.asarray(structure.positions, dtype=np.float64)
    reach = float(np.max(structure.vdw_radii)) + float(probe_radius)
    return positions.min(axis=0) - reach, positions.max(axis=0) + reach


def _fitted(lo: np.ndarray, hi: np.ndarray) -> tuple[np.ndarray, float]:
    """Centre and half edge of the cube whose drift-free core holds the SAS box lo..hi."""
    center = (lo + hi) / 2.0
    extent = float(np.max(hi - center))
    return center, (extent + FIT_PADDING_A) / (1.0 - MARGIN_FRACTION)


def _half_mm(limits: DeviceLimits) -> float:
    """Half edge of the cube inscribed in the device's workspace box (mm)."""
    half_mm = (
        float(np.min(np.asarray(limits.workspace_max_mm) - np.asarray(limits.workspace_min_mm)))
        / 2.0
    )
    if not half_mm > 0:
        raise ValueError("device workspace has no extent")
    return half_mm


def initial_half(
    structure,
    limits: DeviceLimits,
    cube_half_A: float | str | None = None,
    probe_radius: float = DEFAULT_PROBE_RADIUS,
) -> float:
    """The half edge (Å) a session's cube starts with: `cube_half_A` (Å), "fit", or None for
    the default (cheap: no surface search, so the loop may call it)."""
    cube_half_A = validate_cube_half(cube_half_A)
    lo, hi = _sas_box(structure, probe_radius)
    if cube_half_A == CUBE_FIT:
        return _fitted(lo, hi)[1]
    if cube_half_A is None:
        return default_cube_half(float(np.min(hi - lo)), _half_mm(limits))
    return float(cube_half_A)


def default_cube_half(smallest_width_A: float, half_mm: float) -> float:
    """The default half edge (Å): DEFAULT_SCALE_A_PER_MM Å per mm of the device's inscribed
    cube, at most CONTEXT_FRACTION of the molecule's smallest width."""
    return min(DEFAULT_SCALE_A_PER_MM * half_mm, CONTEXT_FRACTION * smallest_width_A)


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

    # ----------------------------------------------------------- construction
    @classmethod
    def initial(
        cls,
        structure,
        limits: DeviceLimits,
        cube_half_A: float | str | None = None,
        probe_radius: float = DEFAULT_PROBE_RADIUS,
        cube_center_A=None,
        surface=None,
    ) -> WorkspaceMapping:
        """The mapping a session starts with (the daemon and the simulated arm share it).

        Half edge: `cube_half_A` (Å), "fit", or None for the default (see the module
        docstring). Centre: `cube_center_A`, else the SAS's centre for a cube that holds
        the molecule, else the surface site (`surface`: a devices.surface.Surface of the
        structure at this probe radius, built here when not given).
        """
        cube_center_A = validate_cube_center(cube_center_A)
        ws_lo = np.asarray(limits.workspace_min_mm, dtype=np.float64)
        ws_hi = np.asarray(limits.workspace_max_mm, dtype=np.float64)
        half_mm = _half_mm(limits)
        fit_center, fit_half = _fitted(*_sas_box(structure, probe_radius))
        half = initial_half(structure, limits, cube_half_A, probe_radius)
        if cube_center_A is not None:
            center = np.asarray(cube_center_A, dtype=np.float64)
        elif half >= fit_half:
            center = fit_center
        else:
            if surface is None:
                from sasprobe.devices.surface import Surface

                surface = Surface.of(structure, probe_radius)
            center = np.asarray(surface.site(half)) - np.array([0.0, 0.0, SITE_SINK * half])
        positions = np.asarray(structure.positions, dtype=np.float64)
        return cls(
            workspace_center_mm=tuple(float(v) for v in (ws_lo + ws_hi) / 2.0),  # type: ignore[arg-type]
            half_mm=half_mm,
            cube_center=[float(v) for v in center],
            cube_half_A=float(half),
            bounds_lo_A=tuple(float(v) for v in positions.min(axis=0)),  # type: ignore[arg-type]
            bounds_hi_A=tuple(float(v) for v in positions.max(axis=0)),  # type: ignore[arg-type]
        )

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
            v = (
                r[3 * axis] * vx + r[3 * axis + 1] * vy + r[3 * axis + 2] * vz
            )  # along this molecule axis
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
        """A new view rotation (validate_rotation's 9 floats), turning about the goal so it does not jump."""
        goal = self.to_molecule(*tip_mm) if tip_mm is not None else None
        self.rotation = tuple(rotation)
        if goal is not None:
            self._anchor(goal, tip_mm)

    def recentre(self, point_A) -> None:
        """Centre the cube on a molecule point (the probe)."""
        self.cube_center = [float(v) for v in point_A]
