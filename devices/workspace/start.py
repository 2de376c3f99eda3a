"""The navigation cube a session starts with: its size and where it sits on the molecule.

The default size (`cube_half_A=None`) gives the physical workspace a useful scale and
the cube context around it: DEFAULT_SCALE_A_PER_MM Å per mm of hand travel (a 14 Å half
edge on an Omni-class arm's 35 mm: the probe's 2.8 Å diameter is 7 mm of hand travel,
and on a large structure's surface the cube holds about 300 atoms, as the navigation
cube of the HaptiMOL thesis' GroEL figure does), but at most CONTEXT_FRACTION of the
molecule's smallest width, so that the cube is a window onto part of the molecule and
the rest shows around it as the backbone trace (crambin: 5.6 Å, a few residues, at
0.16 Å per mm). It starts on the top of the surface (molecule/surface.py), sunk by
SITE_SINK of its half edge so that most of it holds the molecule and the rest is room to
hover. The fitted cube (`cube_half_A="fit"`, or any cube at least that large) holds the
whole solvent accessible surface in its drift-free core, centred on it.
"""

from __future__ import annotations

import math

import numpy as np
from sasprobe.devices.base import DeviceLimits
from sasprobe.devices.workspace.mapping import MARGIN_FRACTION, WorkspaceMapping
from sasprobe.molecule.probe import DEFAULT_PROBE_RADIUS
from sasprobe.molecule.surface import Surface

MAX_CUBE_HALF_A = 10_000.0  # larger navigation cubes are a mistake, not a molecule
FIT_PADDING_A = 3.0  # room around the SAS inside the fitted cube's core (to hover, to approach)
DEFAULT_SCALE_A_PER_MM = 0.4  # the default cube: this many Å per mm of hand travel ...
CONTEXT_FRACTION = 0.2  # ... and a half edge at most this fraction of the molecule's smallest width
SITE_SINK = 0.25  # a zoomed-in cube's centre lies this fraction of its half edge below the site
CUBE_FIT = "fit"  # cube_half_A that fits the whole molecule


def validate_cube_half(value: float | str | None) -> float | str | None:
    """None (the default size), "fit", or a finite positive half edge in Å; ValueError (one
    line) otherwise."""
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


def initial_mapping(
    structure,
    limits: DeviceLimits,
    cube_half_A: float | str | None = None,
    probe_radius: float = DEFAULT_PROBE_RADIUS,
    cube_center_A=None,
    surface: Surface | None = None,
) -> WorkspaceMapping:
    """The mapping a session starts with (the haptic engine and the simulated arm share it).

    Half edge: `cube_half_A` (Å), "fit", or None for the default (see the module
    docstring). Centre: `cube_center_A`, else the SAS's centre for a cube that holds the
    molecule, else the surface site (`surface`: the structure's Surface at this probe
    radius, built here when not given).
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
            surface = Surface.of(structure, probe_radius)
        center = np.asarray(surface.site(half)) - np.array([0.0, 0.0, SITE_SINK * half])
    positions = np.asarray(structure.positions, dtype=np.float64)
    return WorkspaceMapping(
        workspace_center_mm=tuple(float(v) for v in (ws_lo + ws_hi) / 2.0),  # type: ignore[arg-type]
        half_mm=half_mm,
        cube_center=[float(v) for v in center],
        cube_half_A=float(half),
        bounds_lo_A=tuple(float(v) for v in positions.min(axis=0)),  # type: ignore[arg-type]
        bounds_hi_A=tuple(float(v) for v in positions.max(axis=0)),  # type: ignore[arg-type]
    )
