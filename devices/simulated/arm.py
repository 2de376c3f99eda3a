"""The simulated arm, `--device sim[:SCRIPT]` (scripts: scan (default), dive, press, orbit,
random, sweep: the hand's paths, hand_paths.py).

Model (no more than haptic rendering needs): the stylus tip is a point mass with the
arm's viscous damping, moved by a model hand and by the rendered force:

    m a = k_h (target - x) + b_h (target' - v) - b_arm v + F_rendered

The hand is a spring-damper pulling toward its path's target (hand_paths.py),
whose force never exceeds `max_hand_force_n` (default: HAND_RATING_FRACTION of the
device's continuous rating, 0.79 N for the Omni-class arm's 0.88 N): a person does not
lean on the arm harder than its motors can hold, so wherever the path's target lies,
the rendered force that balances the hand stays under the rating (a target far inside
the molecule makes the hand push just under it, not at the amplifier's peak).
The rendered force is held constant over a control period (zero-order hold, as a real
amplifier does) while the motion is integrated in substeps of at most 0.1 ms
(semi-implicit Euler), so sample-and-hold effects (energy gain, instability at low
rates or high stiffness) are real. Parameters are in ArmModel; defaults are an
Omni-class arm (45 g apparent mass) held by a light grip.

Determinism and time: the device has its own clock. `read()` returns the state at
the current simulated time, t_ns = start_ns + k * period_ns, where k counts the
`write_force()` calls; each `write_force()` advances the physics by exactly one
control period (1 / rate_hz) with that force held. Unless `start_ns` is given, the
clock starts on the host's monotonic clock, one period before the first reading: the
daemon's loop reads once a period on a fixed grid, so however late its first read came
within a period, no later reading is stamped after the host's time at that read. It
falls behind the host's clock by the periods no force was written in (ticks the daemon
lost to timing). Nothing else reads a clock, so the motion is a pure function of
(structure, script, seed, options, forces written).

Bookkeeping for tests and benchmarks: `last_force_n` (the last force written; zero
after `close()`), `forces_written`, `nan_writes` (non-finite forces received; they
are applied as zero), `work_mj` (energy the rendered force put into the stylus, the
sum of F . dx over each held period, mJ), `target_mm` (the hand's target now).

Fault injection (for the daemon's tests), by option or method:
- option `faults=["raise@500+20", "nan@900+5", "disconnect@1500", "stall@0"]` or tuples
  (kind, tick, count): at simulated tick `tick` (count of write_force calls) the fault
  starts;
- `inject_fault(kind, count=1)` starts one now.
Buttons (option `button_presses=["0@2000+1500"]`): button 0 is held down from simulated
tick 2000 for 1500 ticks (the clutch, by the daemon's default button map).

Kinds: `raise` - the next `count` reads raise DeviceFault; `nan` - the next `count`
reads return NaN position and velocity; `disconnect` - reads raise DeviceFault until
`reconnect()` is called (with option `failed_reconnects=N`, the first N reconnects
raise DeviceFault too). While a fault lasts, the physics keeps running on the forces
written (the daemon writes zero), so the hand keeps moving as a real one would.
"""

from __future__ import annotations

import dataclasses
import math
import time
from dataclasses import dataclass

import numpy as np
from sasprobe.devices.base import (
    PHANTOM_OMNI_LIMITS,
    DeviceFault,
    DeviceInfo,
    DeviceLimits,
    DeviceState,
    HapticDevice,
)
from sasprobe.devices.simulated.hand_paths import SCRIPTS, HandPath, place_hand_path
from sasprobe.devices.workspace.start import initial_mapping
from sasprobe.molecule.probe import DEFAULT_PROBE_RADIUS
from sasprobe.molecule.surface import Surface

FAULT_KINDS = ("raise", "nan", "disconnect")
# The fastest the daemon runs the simulated arm: its physics keep up with any rate (every
# period is integrated in substeps), so this is the daemon's own ceiling.
MAX_RATE_HZ = 4000.0
MAX_SUBSTEP_S = 1e-4
HAND_RATING_FRACTION = 0.9  # the model hand pushes at most this fraction of the continuous rating


@dataclass(frozen=True)
class ArmModel:
    mass_kg: float = 0.045  # Omni apparent mass at the tip (spec sheet, see research notes)
    arm_damping_n_s_per_m: float = 0.3
    hand_stiffness_n_per_mm: float = 0.2  # a light grip
    hand_damping_n_s_per_m: float = 1.0
    # None: HAND_RATING_FRACTION of the device's continuous rating
    max_hand_force_n: float | None = None


class SimulatedDevice(HapticDevice):
    def __init__(
        self,
        hand_path: HandPath,
        limits: DeviceLimits = PHANTOM_OMNI_LIMITS,
        rate_hz: float = 1000.0,
        arm: ArmModel = ArmModel(),
        start_ns: int | None = None,
        faults=(),
        failed_reconnects: int = 0,
        seed: int = 0,
        button_presses=(),
    ):
        rate_hz = float(rate_hz)
        if not math.isfinite(rate_hz) or rate_hz <= 0 or rate_hz > 100_000:
            raise ValueError(f"simulated control rate must be in (0, 100000] Hz, got {rate_hz:g}")
        self.hand_path = hand_path
        self.limits = dataclasses.replace(
            limits,
            max_rate_hz=MAX_RATE_HZ,
            held_damping_n_s_per_m=arm.arm_damping_n_s_per_m + arm.hand_damping_n_s_per_m,
        )
        self.arm = arm
        self.rate_hz = rate_hz
        self.period_ns = int(round(1e9 / rate_hz))
        self.period_s = self.period_ns * 1e-9
        self.substeps = max(1, math.ceil(self.period_s / MAX_SUBSTEP_S - 1e-9))
        self.start_ns = None if start_ns is None else int(start_ns)  # None: set at the first read
        self.seed = seed
        self.ticks = 0
        self._x = list(hand_path.start)
        self._v = [0.0, 0.0, 0.0]
        self.last_force_n = np.zeros(3)
        self.forces_written = 0
        self.nan_writes = 0
        self.work_mj = 0.0
        self.peak_hand_force_n = 0.0  # the largest force the model hand applied
        self.is_open = False
        self._scheduled = sorted((parse_fault(f) for f in faults), key=lambda f: f[1])
        self._raise_reads = 0
        self._nan_reads = 0
        self._disconnected = False
        self._failed_reconnects = int(failed_reconnects)
        self._presses = [_parse_press(p) for p in button_presses]
        self.max_hand_force_n = float(
            arm.max_hand_force_n
            if arm.max_hand_force_n is not None
            else HAND_RATING_FRACTION * limits.continuous_force_n
        )

    # --------------------------------------------------------------- interface
    @property
    def info(self) -> DeviceInfo:
        return DeviceInfo(
            kind="sim",
            model=f"simulated Omni-class arm ({self.hand_path.name})",
            limits=self.limits,
            details={
                "script": self.hand_path.name,
                "rate_hz": self.rate_hz,
                "seed": self.seed,
                "substeps": self.substeps,
                "mass_kg": self.arm.mass_kg,
                "arm_damping_n_s_per_m": self.arm.arm_damping_n_s_per_m,
                "hand_stiffness_n_per_mm": self.arm.hand_stiffness_n_per_mm,
                "hand_damping_n_s_per_m": self.arm.hand_damping_n_s_per_m,
                "max_hand_force_n": self.max_hand_force_n,
            },
        )

    def open(self) -> None:
        self.is_open = True

    def close(self) -> None:
        self.last_force_n = np.zeros(3)  # a closed device renders no force
        self.is_open = False

    def reconnect(self) -> None:
        if self._failed_reconnects > 0:
            self._failed_reconnects -= 1
            raise DeviceFault("simulated arm: reconnect failed")
        self._disconnected = False
        self.is_open = True

    def inject_fault(self, kind: str, count: int = 1) -> None:
        if kind == "raise":
            self._raise_reads += int(count)
        elif kind == "nan":
            self._nan_reads += int(count)
        elif kind == "disconnect":
            self._disconnected = True
        else:
            raise ValueError(f"unknown fault kind {kind!r} (known: {', '.join(FAULT_KINDS)})")

    def read(self) -> DeviceState:
        if not self.is_open:
            raise DeviceFault("simulated arm is not open")
        while self._scheduled and self._scheduled[0][1] <= self.ticks:
            kind, _, count = self._scheduled.pop(0)
            self.inject_fault(kind, count)
        if self._disconnected:
            raise DeviceFault("simulated arm: link lost")
        if self._raise_reads > 0:
            self._raise_reads -= 1
            raise DeviceFault("simulated arm: read timed out")
        if self.start_ns is None:  # one period before the host's clock at the first reading (below)
            self.start_ns = time.monotonic_ns() - (self.ticks + 1) * self.period_ns
        t_ns = self.start_ns + self.ticks * self.period_ns
        if self._nan_reads > 0:
            self._nan_reads -= 1
            return DeviceState(
                t_ns=t_ns, position_mm=np.full(3, np.nan), velocity_mm_s=np.full(3, np.nan)
            )
        buttons = 0
        for button, first, count in self._presses:
            if first <= self.ticks < first + count:
                buttons |= 1 << button
        return DeviceState(
            t_ns=t_ns,
            position_mm=np.array(self._x),
            velocity_mm_s=np.array(self._v),
            buttons=buttons,
        )

    def write_force(self, force_n) -> None:
        f = [float(v) for v in np.asarray(force_n, dtype=np.float64).reshape(3)]
        if not all(math.isfinite(v) for v in f):
            self.nan_writes += 1
            f = [0.0, 0.0, 0.0]
        magnitude = math.sqrt(f[0] ** 2 + f[1] ** 2 + f[2] ** 2)
        if magnitude > self.limits.max_force_n:  # the amplifier's own limit
            f = [v * self.limits.max_force_n / magnitude for v in f]
        self.last_force_n = np.array(f)
        self.forces_written += 1
        if not self.is_open:
            return
        self._advance(f)

    def zero_force_now(self) -> None:
        """The watchdog's zero: the arm holds no force from now on, and its clock does not move
        (it advances one period per write of the loop, so a run stays a function of those)."""
        self.last_force_n = np.zeros(3)

    # ----------------------------------------------------------------- physics
    @property
    def position_mm(self) -> np.ndarray:
        return np.array(self._x)

    @property
    def time_s(self) -> float:
        return self.ticks * self.period_s

    @property
    def target_mm(self) -> tuple[float, float, float]:
        return self.hand_path.target(self.time_s)

    def _advance(self, f: list[float]) -> None:
        arm = self.arm
        h = self.period_s / self.substeps
        inv_m = 1e3 / arm.mass_kg  # N -> mm/s^2
        kh = arm.hand_stiffness_n_per_mm
        bh = arm.hand_damping_n_s_per_m * 1e-3  # N per mm/s
        ba = arm.arm_damping_n_s_per_m * 1e-3
        limit = self.max_hand_force_n
        x, v = self._x, self._v
        x0 = list(x)
        t0 = self.time_s
        target = self.hand_path.target
        a = target(t0)
        for k in range(self.substeps):
            b = target(t0 + (k + 1) * h)
            hand = [kh * (a[i] - x[i]) + bh * ((b[i] - a[i]) / h - v[i]) for i in range(3)]
            magnitude = math.sqrt(hand[0] ** 2 + hand[1] ** 2 + hand[2] ** 2)
            if magnitude > limit:  # the person yields rather than push harder
                hand = [c * limit / magnitude for c in hand]
            self.peak_hand_force_n = max(self.peak_hand_force_n, min(magnitude, limit))
            for i in range(3):
                v[i] += (hand[i] - ba * v[i] + f[i]) * inv_m * h
                x[i] += v[i] * h
            a = b
        self.work_mj += f[0] * (x[0] - x0[0]) + f[1] * (x[1] - x0[1]) + f[2] * (x[2] - x0[2])
        self.ticks += 1


def _parse_press(spec) -> tuple[int, int, int]:
    """'BUTTON@TICK+COUNT' or (button, tick, count) -> (button, tick, count); ValueError
    otherwise."""
    try:
        if isinstance(spec, str):
            button, _, rest = spec.partition("@")
            tick, _, count = rest.partition("+")
            parsed = (int(button), int(tick or 0), int(count or 1))
        else:
            parsed = tuple(int(v) for v in spec)
            if len(parsed) != 3:
                raise ValueError
    except ValueError:
        raise ValueError(
            f"button press {spec!r}: expected BUTTON@TICK+COUNT, e.g. 0@2000+1500"
        ) from None
    if not 0 <= parsed[0] <= 31 or parsed[1] < 0 or parsed[2] < 1:
        raise ValueError(f"button press {spec!r}: button 0..31, tick >= 0, count >= 1")
    return parsed  # type: ignore[return-value]


def parse_fault(spec, kinds: tuple[str, ...] = FAULT_KINDS) -> tuple[str, int, int]:
    """'kind@tick+count' or (kind, tick[, count]) -> (kind, tick, count); ValueError in one line
    unless kind is known, tick a whole number ≥ 0 and count a whole number ≥ 1."""
    if isinstance(spec, str):
        kind, at, rest = spec.strip().partition("@")
        tick, plus, count = rest.partition("+")
        if not at or not _whole(tick) or (plus and not _whole(count)):
            raise ValueError(f"fault '{spec}' is not KIND@TICK or KIND@TICK+COUNT (whole numbers)")
        parsed = (kind, int(tick), int(count) if plus else 1)
    else:
        items = tuple(spec)
        parsed = (str(items[0]), int(items[1]), int(items[2]) if len(items) > 2 else 1)
    if parsed[0] not in kinds:
        raise ValueError(f"unknown fault kind {parsed[0]!r} (known: {', '.join(kinds)})")
    if parsed[1] < 0 or parsed[2] < 1:
        raise ValueError(f"fault '{spec}': the tick must be ≥ 0 and the count ≥ 1")
    return parsed


def _whole(text: str) -> bool:
    return text.isdigit() and text.isascii()


def make_simulated(argument: str | None, **options) -> SimulatedDevice:
    """Factory for `--device sim[:SCRIPT]`.

    Options: structure (default: embedded 1CRN), rate_hz (1000), seed (0), limits,
    probe_radius_A, cube_half_A, cube_center_A (so the hand's path is placed with the
    haptic engine's mapping), arm (ArmModel), start_ns, faults, failed_reconnects,
    button_presses. Unknown options are ignored.
    """
    from sasprobe.devices.base import DeviceOpenError

    name = (argument or "scan").strip().lower()
    if name not in SCRIPTS:
        raise DeviceOpenError(
            f"unknown simulated-arm script '{name}' (known: {', '.join(SCRIPTS)})"
        )
    structure = options.get("structure")
    if structure is None:
        from sasprobe.molecule import load_default

        structure = load_default()
    limits = options.get("limits") or PHANTOM_OMNI_LIMITS
    probe = float(options.get("probe_radius_A") or DEFAULT_PROBE_RADIUS)
    seed = int(options.get("seed") or 0)
    surface = Surface.of(structure, probe)
    mapping = initial_mapping(
        structure, limits, options.get("cube_half_A"), probe, options.get("cube_center_A"), surface
    )
    hand_path = place_hand_path(
        name, structure, mapping, probe_radius=probe, seed=seed, surface=surface
    )
    return SimulatedDevice(
        hand_path,
        limits=limits,
        rate_hz=options.get("rate_hz") or 1000.0,
        arm=options.get("arm") or ArmModel(),
        start_ns=options.get("start_ns"),
        faults=options.get("faults") or (),
        failed_reconnects=int(options.get("failed_reconnects") or 0),
        seed=seed,
        button_presses=options.get("button_presses") or (),
    )
