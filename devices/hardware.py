"""What every driver of real hardware shares: the `HardwareDriver` base (a reconnect that
reports a still-missing device as a fault), force clamping, the limits of an arm with a
published workspace sphere, velocity estimation, and the hook that points a driver at an
emulator. Rotations as quaternions are devices/kinematics.py's."""

from __future__ import annotations

import math

import numpy as np
from sasprobe.devices.base import (
    DEFAULT_RATE_HZ,
    DeviceFault,
    DeviceLimits,
    DeviceOpenError,
    HapticDevice,
)

ZERO_FORCE = np.zeros(3)


def clamp_force(force_n, max_force_n: float) -> np.ndarray:
    """A finite force no longer than `max_force_n`, pointing where the command pointed.

    Anything not finite (NaN, inf) becomes zero: a device is never sent NaN.
    """
    f = np.asarray(force_n, dtype=float).reshape(-1)
    if f.shape != (3,) or not np.all(np.isfinite(f)):
        return ZERO_FORCE.copy()
    biggest = float(np.max(np.abs(f)))
    if biggest == 0.0:
        return f
    unit = f / biggest  # normalise first so huge commands do not overflow the norm
    norm = biggest * float(np.linalg.norm(unit))
    if norm > max_force_n:
        f = unit * (max_force_n / float(np.linalg.norm(unit)))
    return f


def sphere_limits(
    radius_m: float,
    force_n: float,
    stiffness_n_per_m: float,
    damping_n_s_per_m: float,
    nominal_rate_hz: float = DEFAULT_RATE_HZ,
    max_rate_hz: float = DEFAULT_RATE_HZ,
) -> DeviceLimits:
    """The limits of an arm whose maker publishes a workspace sphere and one force limit: the
    box inside the sphere (its corners on it), and that force as both peak and continuous."""
    half = radius_m * 1000.0 / math.sqrt(3.0)
    return DeviceLimits(
        max_force_n=force_n,
        continuous_force_n=force_n,
        max_stiffness_n_per_mm=stiffness_n_per_m / 1000.0,
        max_damping_n_s_per_m=damping_n_s_per_m,
        workspace_min_mm=(-half, -half, -half),
        workspace_max_mm=(half, half, half),
        nominal_rate_hz=nominal_rate_hz,
        max_rate_hz=max_rate_hz,
    )


class VelocityFilter:
    """Finite differences through a first-order low-pass (the usual haptic estimate).

    The cut-off trades noise against delay; 100 Hz suits encoder-quantised arms at 1 kHz.
    """

    def __init__(self, cutoff_hz: float = 100.0):
        self.cutoff_hz = cutoff_hz
        self.reset()

    def reset(self) -> None:
        self._t_ns: int | None = None
        self._p = np.zeros(3)
        self.velocity = np.zeros(3)

    def update(self, t_ns: int, position) -> np.ndarray:
        p = np.asarray(position, dtype=float)
        if self._t_ns is not None and t_ns > self._t_ns:
            dt = (t_ns - self._t_ns) * 1e-9
            raw = (p - self._p) / dt
            alpha = 1.0 - math.exp(-2.0 * math.pi * self.cutoff_hz * dt)
            self.velocity = self.velocity + alpha * (raw - self.velocity)
        self._t_ns, self._p = t_ns, p
        return self.velocity.copy()


def factory_from_environment(variable: str):
    """The object `module:function()` named by an environment variable, or None when unset.

    How a test points a driver running in another process (the daemon, the CLI) at an
    emulator that stands in for a library boundary (a pyusb backend, the hidapi module).
    """
    import importlib
    import os

    spec = os.environ.get(variable)
    if not spec:
        return None
    module_name, _, function = spec.partition(":")
    try:
        return getattr(importlib.import_module(module_name), function)()
    except (ImportError, AttributeError) as exc:
        raise DeviceOpenError(f"{variable}={spec} is not usable: {exc}") from None


class HardwareDriver(HapticDevice):
    """A driver of real hardware: `reconnect()` reports a still-missing device as a fault.

    `open()` raises DeviceOpenError for the user to read; during a session the daemon
    keeps retrying `reconnect()`, which must raise DeviceFault while the cable is out.
    """

    force = ZERO_FORCE  # the force last asked for, after clamping (drivers assign a new array)

    @property
    def last_force_n(self) -> np.ndarray:
        """The force the device was last told to render (zero after `close()`)."""
        return np.array(self.force, dtype=float)

    def reconnect(self) -> None:
        self.close()
        try:
            self.open()
        except DeviceOpenError as exc:
            raise DeviceFault(f"device still unavailable: {exc}") from None
