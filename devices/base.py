"""The device interface every haptic (or input-only) device implements.

The device frame, one for every driver: x to the user's right, y up, z toward the user
(right-handed), in millimetres, with the origin at the centre of the device's
workspace; forces are newtons in that frame. Each driver maps its device's own frame
onto this one. Time is integer nanoseconds on the monotonic clock
(`time.monotonic_ns()`), or a driver's own clock mapped onto it.

Contract for the daemon's fixed-rate loop:
- `read()` returns the newest state and must not block longer than the driver's read
  timeout; a lost, late or garbled device raises DeviceFault (never hangs);
- a state's `t_ns` is when it was sampled on the host's monotonic clock: it never
  decreases from one reading to the next and is never later than `read()`'s return
  (clients get it as the pose's `device_t_ns`, protocol/README.md "Device time");
- `write_force()` sends one force command; a device without force output ignores it;
  `withhold_force()` sends zero on a tick whose force the daemon's safety guard withheld
  (a failed or late read, the first tick of a ramp): a zero that says nothing of where the
  hand is, where `write_force(0)` says the hand is in free space;
- on DeviceFault the daemon writes zero force, flags the fault and keeps calling
  `read()` (after `reconnect()` when the driver supports it) until the device answers;
- `close()` must leave the device producing zero force.
"""

from __future__ import annotations

import abc
from dataclasses import dataclass, field

import numpy as np

from sasprobe.common.errors import UserError

IDENTITY_QUATERNION = (1.0, 0.0, 0.0, 0.0)  # (w, x, y, z)
DEFAULT_RATE_HZ = 1000.0  # the control rate haptics needs, which most arms declare
# The viscous damping at the tip of an arm held by a light grip, the b of the passivity
# bound K < 2(b - B)/T: the simulated Omni-class arm's own 0.3 N·s/m and its model hand's
# 1.0 (devices/simulated/arm.py's ArmModel). No maker publishes an arm's, so every arm is
# taken to be held like the simulated one (docs/haptics.md#default-stiffness).
HELD_DAMPING_N_S_PER_M = 1.3


class DeviceFault(RuntimeError):
    """A device that no longer answers correctly at run time (timeout, lost link, bad data)."""


class DeviceOpenError(UserError):
    """A device that cannot be opened (unknown, missing, no permission, missing firmware)."""


@dataclass(frozen=True)
class DeviceLimits:
    """What the hardware can safely render; the daemon clamps every command to these."""

    max_force_n: float  # peak force ever commanded
    continuous_force_n: float  # force the motors sustain without overheating
    max_stiffness_n_per_mm: float  # stiffest virtual spring the device renders stably
    max_damping_n_s_per_m: float
    workspace_min_mm: tuple[float, float, float]  # usable box in the device frame
    workspace_max_mm: tuple[float, float, float]
    # the loop rate the daemon runs the device at by default, and the fastest its link keeps up with
    nominal_rate_hz: float = DEFAULT_RATE_HZ
    max_rate_hz: float = DEFAULT_RATE_HZ
    has_force_output: bool = True
    held_damping_n_s_per_m: float = HELD_DAMPING_N_S_PER_M  # the arm's and the hand's, at the tip

    @property
    def workspace_center_mm(self) -> np.ndarray:
        return (np.asarray(self.workspace_min_mm) + np.asarray(self.workspace_max_mm)) / 2.0


# A PHANTOM Omni class arm: 3.3 N peak and 0.88 N continuous (HDAPI examples), CHAI3D's
# 0.7 N/mm stiffness and 5 N·s/m damping limits, ~160 x 120 x 70 mm workspace.
PHANTOM_OMNI_LIMITS = DeviceLimits(
    max_force_n=3.3,
    continuous_force_n=0.88,
    max_stiffness_n_per_mm=0.7,
    max_damping_n_s_per_m=5.0,
    workspace_min_mm=(-80.0, -60.0, -35.0),
    workspace_max_mm=(80.0, 60.0, 35.0),
    nominal_rate_hz=1000.0,
)


@dataclass(frozen=True)
class DeviceInfo:
    kind: str  # the --device scheme, e.g. "sim", "replay", "falcon"
    model: str  # human-readable model name
    limits: DeviceLimits
    serial: str = ""
    details: dict = field(default_factory=dict)  # driver-specific, JSON-serialisable

    def as_dict(self) -> dict:
        lim = self.limits
        return {
            "kind": self.kind,
            "model": self.model,
            "serial": self.serial,
            "limits": {
                "max_force_n": lim.max_force_n,
                "continuous_force_n": lim.continuous_force_n,
                "max_stiffness_n_per_mm": lim.max_stiffness_n_per_mm,
                "max_damping_n_s_per_m": lim.max_damping_n_s_per_m,
                "workspace_min_mm": list(lim.workspace_min_mm),
                "workspace_max_mm": list(lim.workspace_max_mm),
                "nominal_rate_hz": lim.nominal_rate_hz,
                "max_rate_hz": lim.max_rate_hz,
                "has_force_output": lim.has_force_output,
            },
            "details": dict(self.details),
        }


@dataclass
class DeviceState:
    """One reading of the device."""

    t_ns: int  # device timestamp, monotonic ns
    position_mm: np.ndarray  # (3,) stylus tip in the device frame
    # (w, x, y, z)
    orientation: np.ndarray = field(default_factory=lambda: np.array(IDENTITY_QUATERNION))
    velocity_mm_s: np.ndarray = field(default_factory=lambda: np.zeros(3))  # (3,)
    buttons: int = 0  # bit i = button i pressed
    calibrated: bool = True  # False: the daemon must not output force yet

    def is_finite(self) -> bool:
        return bool(
            np.all(np.isfinite(self.position_mm))
            and np.all(np.isfinite(self.orientation))
            and np.all(np.isfinite(self.velocity_mm_s))
        )


class HapticDevice(abc.ABC):
    """Base class of every device: hardware drivers, the simulated arm, the replay device.

    Besides the abstract interface it has explicit defaults for what only some devices
    do, so the daemon treats every device alike: a device that replays a recorded
    session overrides the three `recorded_*` methods; a device that can tell what force
    it holds sets `last_force_n`.
    """

    # the force the device itself holds now; None: it cannot tell
    last_force_n: np.ndarray | None = None

    @property
    @abc.abstractmethod
    def info(self) -> DeviceInfo: ...

    @abc.abstractmethod
    def open(self) -> None: ...

    @abc.abstractmethod
    def close(self) -> None: ...

    @abc.abstractmethod
    def read(self) -> DeviceState: ...

    @abc.abstractmethod
    def write_force(self, force_n: np.ndarray) -> None: ...

    def withhold_force(self) -> None:
        """Zero force on a tick whose force the daemon's safety guard withheld (a failed or late
        read, the first tick of a ramp): unlike `write_force(0)`, a zero that says nothing of
        where the hand is. A driver that watches the daemon's zeros (OpenHaptics, after a force
        error) tells the two apart; for any other this default is the same write."""
        self.write_force(np.zeros(3))

    def zero_force_now(self) -> None:
        """Zero force from another thread while the loop is stalled (the daemon's watchdog calls it,
        holding the lock the loop writes with). A driver whose write is safe from a second thread
        needs nothing more than this default; devices/README.md says, per driver, what holds."""
        self.write_force(np.zeros(3))

    def reconnect(self) -> None:
        """Try to re-establish a lost link; raises DeviceFault while the device is still gone."""
        self.close()
        self.open()

    def recorded_session(self):
        """The recorded session a device replays (its structure, settings and rate); None
        for a live device."""
        return None

    def take_recorded_events(self) -> list[dict]:
        """Recorded control commands due at the tick read last, in order; none for a live device."""
        return []

    def recorded_late_periods(self) -> float:
        """How many periods late the tick read last started in the recording; 0 for a live
        device."""
        return 0.0

    def __enter__(self) -> HapticDevice:
        self.open()
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
