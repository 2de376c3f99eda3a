"""One tick's computation, shared by the live daemon and `sasprobe replay --verify`.

device state (or the reason there is none) → haptic engine → safety guard → force,
flags and the pose fields. It reads no clock and touches no socket, so feeding it a
recording's inputs reproduces the recorded forces bit for bit.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass

import numpy as np
from sasprobe.daemon.haptics.safety import GuardResult, SafetyGuard, state_is_finite
from sasprobe.devices.base import DeviceState
from sasprobe.devices.workspace.mapping import IDENTITY
from sasprobe.protocol.pose import (
    FLAG_CLAMPED,
    FLAG_CLUTCHED,
    FLAG_CONTACT,
    FLAG_DRIFTING,
    FLAG_FAULT,
    FLAG_RAMPING,
    Pose,
)

log = logging.getLogger("sasprobe")

_ZERO3 = np.zeros(3)  # shared, read-only defaults of pose fields
_ZERO3.flags.writeable = False
_IDENTITY = np.array([1.0, 0.0, 0.0, 0.0])
_IDENTITY.flags.writeable = False


@dataclass
class TickResult:
    force_n: np.ndarray  # the force to write (safe)
    flags: int
    guard: GuardResult
    output: object | None  # the engine's HapticOutput, None when it did not run


class HapticPipeline:
    """Owns the haptic engine and the safety guard; used by one thread only (the loop)."""

    def __init__(self, engine, guard: SafetyGuard) -> None:
        self.engine = engine
        self.guard = guard
        self.last_output = None  # newest engine output (poses keep showing it during faults)
        self.engine_errors = 0
        self.view_rotation = IDENTITY  # the workspace view's turn, kept across engines
        self.clutched = False
        self.device_t_ns = 0  # the newest device state's time (poses repeat it while reads fail)

    def replace_engine(self, engine) -> None:
        """Swap in an engine built elsewhere (new structure or settings); forces ramp in again.
        The view's turn and the clutch carry over to it."""
        self.engine = engine
        self._carry_workspace()
        self.last_output = None
        self.guard.restart_ramp()

    def _carry_workspace(self) -> None:
        if self.view_rotation != IDENTITY:
            self.engine.set_view(self.view_rotation)
        self.engine.set_clutch(self.clutched)

    # ---------------------------------------------- the workspace (view, clutch, recentre)
    def set_view(self, rotation) -> None:
        """The view turned: the workspace turns with it (validate_rotation's 9 floats)."""
        self.view_rotation = tuple(rotation)
        self.engine.set_view(self.view_rotation)

    def set_clutch(self, held: bool) -> None:
        """Clutch held or released; on release forces ramp in again (the hand may have moved
        while nothing pushed back)."""
        held = bool(held)
        if held == self.clutched:
            return
        self.clutched = held
        self.engine.set_clutch(held)
        if not held:
            self.guard.restart_ramp()

    def recentre(self) -> None:
        """The cube centred on the probe; the proxy is unseated and forces ramp in again."""
        self.engine.recentre()
        self.guard.restart_ramp()

    def reconnected(self) -> None:
        """The device was lost and is back: the hand may be anywhere, so unseat the proxy
        (no force until the probe is in free space) and ramp in again. Shorter faults keep
        the proxy where it was: it follows the tip along the surface, never through it."""
        self.engine.reset()
        self.guard.restart_ramp()

    def restart(self, engine) -> None:
        """A fresh engine and guard: all haptic state re-anchored (a recording starts here)."""
        self.engine = engine
        self._carry_workspace()
        self.guard = SafetyGuard(
            self.guard.limits, self.guard.ramp_ns / 1e9, self.guard.late_limit_periods
        )
        self.last_output = None

    def step(
        self, state: DeviceState | None, read_error: str | None, late_periods: float
    ) -> TickResult:
        if state is not None:
            self.device_t_ns = int(state.t_ns)
        reason = self.guard.check(state, read_error, late_periods)
        output = None
        force = None
        ramp_again = True  # unless the engine ran cleanly and only the timing was off
        if reason is None or (read_error is None and state is not None and state_is_finite(state)):
            # A late tick still steps the engine, so the proxy keeps following the tip.
            try:
                output = self.engine.step(state)
            except Exception as exc:  # a bug must cost force, never the loop
                self.engine_errors += 1
                if self.engine_errors <= 3:
                    log.error("haptic engine failed: %s: %s", type(exc).__name__, exc)
                reason = reason or f"haptic engine error: {type(exc).__name__}"
            else:
                force = output.force_n
                self.last_output = output
                ramp_again = bool(output.fault)
                if output.fault and reason is None:
                    reason = "haptic engine fault"
        guard = self.guard.filter(force, state, reason, ramp_again)
        flags = 0
        if guard.fault:
            flags |= FLAG_FAULT
        elif guard.ramp < 1.0:
            flags |= FLAG_RAMPING
        if guard.clamped:
            flags |= FLAG_CLAMPED
        if output is not None:
            flags |= (FLAG_CONTACT if output.contact else 0) | (
                FLAG_DRIFTING if output.drifting else 0
            )
            flags |= FLAG_CLAMPED if output.clamped else 0
            flags |= FLAG_CLUTCHED if output.clutched else 0
        return TickResult(guard.force_n, flags, guard, output)

    def pose(
        self, seq: int, state: DeviceState | None, result: TickResult, publish_t_ns: int
    ) -> Pose:
        """The pose message of the tick `step` computed last. When the engine did not run (a
        failed read, non-finite values) it repeats the last known geometry and device time, and
        touches nothing: the contact flag and `touched_atom` always describe the same tick."""
        out = result.output if result.output is not None else self.last_output
        # no NaN on the wire
        valid = state is not None and (result.output is not None or state_is_finite(state))
        touched = result.output.touched_atoms if result.output is not None else ()
        return Pose(
            seq=seq,
            device_t_ns=self.device_t_ns,
            publish_t_ns=publish_t_ns,
            proxy_A=out.proxy_A if out is not None else _ZERO3,
            goal_A=out.goal_A if out is not None else _ZERO3,
            force_N=result.force_n,
            tip_mm=state.position_mm if valid else _ZERO3,
            orientation=state.orientation if valid else _IDENTITY,
            buttons=state.buttons if valid else 0,
            touched_atom=touched[0] if touched else -1,
            flags=result.flags,
            cube_center_A=out.cube_center_A if out is not None else _ZERO3,
            cube_half_A=out.cube_half_A if out is not None else 0.0,
        )
