"""Force safety between the haptic engine and the device: watchdog, ramp and clamp.

Every tick the guard receives what happened (the device state or the reason the read
failed, how late the tick started, the engine's force) and returns the force that may
be written:

- watchdog: a failed or late device read, non-finite state or force, or a tick more
  than `late_limit_periods` periods late gives zero force and the fault flag; the
  first good tick afterwards recovers;
- ramp: after start and after every recovery (and while the device is uncalibrated),
  force is scaled from 0 to 1 over `ramp_s` of device time, so a hand resting inside
  the surface is not kicked;
- clamp: the force's magnitude never exceeds the device's max force (direction kept).

The guard is a pure function of its inputs and its own state (no wall clock): replaying
a recording's inputs reproduces its forces exactly.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from sasprobe.devices.base import DeviceLimits, DeviceState

ZERO_FORCE = np.zeros(3)
RAMP_S = 1.0
LATE_LIMIT_PERIODS = 3.0


@dataclass(frozen=True)
class GuardResult:
    force_n: np.ndarray  # what may be written to the device
    fault: bool  # the watchdog zeroed the force this tick
    reason: str | None  # why (one line), when fault
    clamped: bool  # the magnitude was cut to the device limit
    ramp: float  # 0..1, the ramp factor applied
    recovered: bool  # first good tick after a fault (for the log)


class SafetyGuard:
    def __init__(
        self,
        limits: DeviceLimits,
        ramp_s: float = RAMP_S,
        late_limit_periods: float = LATE_LIMIT_PERIODS,
    ) -> None:
        self.limits = limits
        self.ramp_ns = int(ramp_s * 1e9)
        self.late_limit_periods = late_limit_periods
        self._ramp_start_ns: int | None = None  # device time the current ramp began
        self._faulted = False
        self._ramp = 0.0  # the last ramp factor applied
        self.fault_ticks = 0
        self.faults = 0  # transitions into the fault state
        self.clamped_ticks = 0
        self.last_reason: str | None = None

    @property
    def faulted(self) -> bool:
        return self._faulted

    def restart_ramp(self) -> None:
        """Ramp again from zero (a new structure or engine, a reconnect)."""
        self._ramp_start_ns = None

    def check(
        self, state: DeviceState | None, read_error: str | None, late_periods: float
    ) -> str | None:
        """The watchdog's reason to zero force before the engine runs, or None."""
        if read_error is not None:
            return f"device read failed: {read_error}"
        if state is None:
            return "no device state"
        if not state_is_finite(state):
            return "non-finite device state"
        if late_periods > self.late_limit_periods:
            return f"tick {late_periods:.1f} periods late"
        return None

    def filter(
        self, force_n, state: DeviceState | None, reason: str | None, ramp_again: bool = True
    ) -> GuardResult:
        """Apply watchdog, ramp and clamp to the engine's force (None when the engine did not run).

        `ramp_again`: whether a fault restarts the ramp. Faults where the device or the
        engine failed do (the hand may have moved meanwhile); a merely late tick does not.
        """
        fx = fy = fz = 0.0
        if reason is None:
            try:
                fx, fy, fz = np.asarray(force_n, dtype=np.float64).tolist()
            except (TypeError, ValueError):  # None, or not 3 numbers
                fx = math.nan
            if not (math.isfinite(fx) and math.isfinite(fy) and math.isfinite(fz)):
                reason, ramp_again = "non-finite force from the haptic engine", True
        if reason is not None:
            if not self._faulted:
                self.faults += 1
            self._faulted = True
            self.fault_ticks += 1
            self.last_reason = reason
            if ramp_again:
                self._ramp_start_ns = None
            return GuardResult(
                ZERO_FORCE.copy(), True, reason, False, 0.0 if ramp_again else self._ramp, False
            )
        recovered = self._faulted
        self._faulted = False
        if not state.calibrated or not self.limits.has_force_output:
            self._ramp_start_ns = None
            return GuardResult(ZERO_FORCE.copy(), False, None, False, 0.0, recovered)
        if self._ramp_start_ns is None:
            self._ramp_start_ns = state.t_ns
        ramp = self._ramp = (
            1.0
            if self.ramp_ns <= 0
            else min(max((state.t_ns - self._ramp_start_ns) / self.ramp_ns, 0.0), 1.0)
        )
        fx, fy, fz = fx * ramp, fy * ramp, fz * ramp
        magnitude = math.sqrt(fx * fx + fy * fy + fz * fz)
        clamped = magnitude > self.limits.max_force_n
        if clamped:
            scale = self.limits.max_force_n / magnitude
            fx, fy, fz = fx * scale, fy * scale, fz * scale
            self.clamped_ticks += 1
        return GuardResult(np.array((fx, fy, fz)), False, None, clamped, ramp, recovered)


def state_is_finite(state: DeviceState) -> bool:
    """DeviceState.is_finite() in plain floats (a few µs cheaper, and it runs every tick)."""
    values = state.position_mm.tolist() + state.velocity_mm_s.tolist() + state.orientation.tolist()
    return all(map(math.isfinite, values))
