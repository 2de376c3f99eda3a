"""Haptic settings: the dataclass the engine takes, and the plain dicts the daemon keeps.

The daemon, the control server and `replay --verify` all check settings here, so a
change is applied the same way live and in a replay. Changes to REBUILD_FIELDS need a
new engine (a new grid), built away from the loop because building the grid of a large
structure takes longer than a tick; the others are applied in the loop with
`HapticEngine.update()`.

The default stiffness is the arm's own at the loop's rate (`default_stiffness`): half the
largest that stays stable there, the smaller of the arm's rated maximum and the passivity
bound of a sampled wall, K < 2(b − B)/T (Colgate & Schenkel; b the damping of the arm and
the hand at its tip, B the contact's virtual damping, T the loop period), so a faster loop
gives a stiffer contact where the arm's rating allows it (docs/haptics.md#default-stiffness;
`sasprobe bench haptics`' stability map measures the bound on the simulated arm).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from sasprobe.devices.base import DeviceLimits
from sasprobe.devices.workspace.start import validate_cube_center, validate_cube_half
from sasprobe.molecule.probe import DEFAULT_PROBE_RADIUS, check_probe_radius
from sasprobe.protocol.scene import HAPTIC_METHODS

# What the daemon publishes and a control `set` may change (the cube centre is fixed per session).
HAPTIC_FIELDS = (
    "probe_radius_A",
    "method",
    "stiffness_n_per_mm",
    "damping_n_s_per_m",
    "cube_half_A",
)
REBUILD_FIELDS = frozenset({"probe_radius_A"})  # a new grid: built off the loop
STIFFNESS_MARGIN = 0.5  # the default is this fraction of the largest stable stiffness
MIN_DEFAULT_STIFFNESS_N_PER_MM = 0.05  # where no stiffness is passive (B ≥ b): a soft contact


def passivity_bound(limits: DeviceLimits, rate_hz: float, damping_n_s_per_m: float) -> float:
    """2(b − B)/T in N/mm: the stiffest sampled wall that stays passive on this arm."""
    return 2.0 * (limits.held_damping_n_s_per_m - damping_n_s_per_m) * rate_hz / 1000.0


def default_stiffness(limits: DeviceLimits, rate_hz: float, damping_n_s_per_m: float) -> float:
    """The arm's default contact stiffness (N/mm) at a loop rate and virtual damping."""
    stable = min(limits.max_stiffness_n_per_mm, passivity_bound(limits, rate_hz, damping_n_s_per_m))
    return max(STIFFNESS_MARGIN * stable, MIN_DEFAULT_STIFFNESS_N_PER_MM)


@dataclass
class HapticSettings:
    probe_radius_A: float = DEFAULT_PROBE_RADIUS
    method: str = HAPTIC_METHODS[0]  # the god-object proxy; "penalty" is the textbook baseline
    stiffness_n_per_mm: float | None = None  # None: the arm's default at the loop's rate
    damping_n_s_per_m: float = 0.2
    # navigation-cube half edge (Å); None: the default size; "fit": the molecule
    cube_half_A: float | str | None = None
    cube_center_A: tuple[float, float, float] | None = None  # None = centre of the molecule

    def validated(self, limits: DeviceLimits, rate_hz: float | None = None) -> HapticSettings:
        """A checked copy, the default stiffness filled in for the loop's rate (None: the
        device's default rate); ValueError with one clear line on a bad value."""
        radius = check_probe_radius(self.probe_radius_A)
        if self.method not in HAPTIC_METHODS:
            raise ValueError(
                f"unknown haptic method {self.method!r} (known: {', '.join(HAPTIC_METHODS)})"
            )
        damping = _finite(self.damping_n_s_per_m, "damping")
        if damping < 0 or damping > limits.max_damping_n_s_per_m:
            raise ValueError(
                f"damping must be in [0, {limits.max_damping_n_s_per_m:g}] N·s/m for this "
                f"device, got {damping:g}"
            )
        if self.stiffness_n_per_mm is None:
            stiffness = default_stiffness(limits, rate_hz or limits.nominal_rate_hz, damping)
        else:
            stiffness = _finite(self.stiffness_n_per_mm, "stiffness")
        if stiffness <= 0 or stiffness > limits.max_stiffness_n_per_mm:
            raise ValueError(
                f"stiffness must be in (0, {limits.max_stiffness_n_per_mm:g}] N/mm for this "
                f"device, got {stiffness:g}"
            )
        return HapticSettings(
            probe_radius_A=radius,
            method=self.method,
            stiffness_n_per_mm=stiffness,
            damping_n_s_per_m=damping,
            cube_half_A=validate_cube_half(self.cube_half_A),
            cube_center_A=validate_cube_center(self.cube_center_A),
        )


def _finite(value, name: str) -> float:
    try:
        value = float(value)
    except (TypeError, ValueError):
        raise ValueError(f"{name} must be a number, got {value!r}") from None
    if not math.isfinite(value):
        raise ValueError(f"{name} must be finite, got {value}")
    return value


def validate_settings(settings: dict, limits: DeviceLimits, rate_hz: float | None = None) -> dict:
    """Complete and check a settings dict (HAPTIC_FIELDS; a missing stiffness is the arm's
    default at `rate_hz`); ValueError with one clear line."""
    try:
        checked = HapticSettings(**settings).validated(limits, rate_hz)
    except TypeError as exc:  # an unknown field name
        raise ValueError(str(exc)) from None
    return {name: getattr(checked, name) for name in HAPTIC_FIELDS}


def split_changes(changes: dict) -> tuple[dict, dict]:
    """(haptic engine fields, scene-only fields) of a `set`."""
    haptic = {k: v for k, v in changes.items() if k in HAPTIC_FIELDS}
    return haptic, {k: v for k, v in changes.items() if k not in HAPTIC_FIELDS}


def needs_rebuild(haptic_changes: dict) -> bool:
    return bool(REBUILD_FIELDS & set(haptic_changes))
