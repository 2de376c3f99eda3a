"""Test-only stand-ins until the haptics branch (HapticRenderer, `sim`) lands on main.

TestArm: a deterministic arm (device time = ticks × period) sweeping through a sphere,
with fault injection. SpringEngine: force = stiffness × penetration into that sphere.
"""

from __future__ import annotations

import math
import sys
from dataclasses import dataclass, replace

import numpy as np

from sasprobe.devices.base import PHANTOM_OMNI_LIMITS, DeviceFault, DeviceInfo, DeviceState, HapticDevice

SPHERE_RADIUS_MM = 15.0


class TestArm(HapticDevice):
    def __init__(self, argument: str | None = None, rate_hz: float | None = 1000.0, **options) -> None:
        self.period_ns = int(1e9 / (rate_hz or 1000.0))
        self.faults = []  # (kind, first tick, ticks)
        for part in filter(None, (argument or "").split(",")):
            kind, _, span = part.partition("@")
            start, _, count = span.partition("+")
            self.faults.append((kind, int(start), int(count or 1)))
        self.n = 0
        self.last_force_n = np.zeros(3)
        self.writes = 0
        self.opened = False

    @property
    def info(self) -> DeviceInfo:
        return DeviceInfo(kind="testarm", model="test arm", limits=PHANTOM_OMNI_LIMITS)

    def open(self) -> None:
        self.opened = True

    def close(self) -> None:
        self.last_force_n = np.zeros(3)
        self.opened = False

    def _fault(self) -> str | None:
        for kind, start, count in self.faults:
            if start <= self.n < start + count:
                return kind
        return None

    def read(self) -> DeviceState:
        fault = self._fault()
        if fault == "timeout":
            raise DeviceFault("read timed out")
        if fault == "exception":
            raise DeviceFault("link lost")
        t = self.n * self.period_ns
        phase = self.n * 2e-3
        radius = 12.0 + 6.0 * math.sin(3 * phase)  # in and out of the sphere
        position = np.array([radius * math.cos(phase), radius * math.sin(phase), 3.0 * math.sin(5 * phase)])
        if fault == "nan":
            position[1] = math.nan
        velocity = np.array([-40.0 * math.sin(phase), 40.0 * math.cos(phase), 30.0 * math.cos(5 * phase)])
        return DeviceState(t_ns=t, position_mm=position, velocity_mm_s=velocity, buttons=self.n // 1000 % 2)

    def write_force(self, force_n) -> None:
        self.last_force_n = np.asarray(force_n, dtype=float).copy()
        self.writes += 1
        if self.opened:
            self.n += 1  # like the sim: every write advances one control period


def open_testarm(argument=None, **options):
    return TestArm(argument, **options)


@dataclass
class SpringSettings:
    probe_radius_A: float = 1.4
    method: str = "proxy"
    stiffness_n_per_mm: float = 0.3
    damping_n_s_per_m: float = 0.2
    cube_half_A: float | None = None

    def validated(self, limits):
        if not 0 < self.stiffness_n_per_mm <= limits.max_stiffness_n_per_mm:
            raise ValueError(f"stiffness must be in (0, {limits.max_stiffness_n_per_mm:g}] N/mm")
        if self.method not in ("proxy", "penalty"):
            raise ValueError(f"unknown haptic method {self.method!r}")
        return replace(self)


@dataclass
class SpringOutput:
    force_n: np.ndarray
    proxy_A: np.ndarray
    goal_A: np.ndarray
    touched_atoms: tuple
    contact: bool
    clamped: bool
    drifting: bool
    fault: bool
    cube_center_A: np.ndarray
    cube_half_A: float


class SpringEngine:
    def __init__(self, structure, limits, settings: SpringSettings) -> None:
        self.limits = limits
        self.settings = settings
        self.structure = structure
        self.resets = 0

    def reset(self) -> None:
        self.resets += 1

    def update(self, **changes) -> None:
        self.settings = replace(self.settings, **changes).validated(self.limits)

    def step(self, state: DeviceState) -> SpringOutput:
        p = np.asarray(state.position_mm, dtype=float)
        if not np.all(np.isfinite(p)):
            return SpringOutput(np.zeros(3), p, p, (), False, False, False, True, np.zeros(3), 10.0)
        r = float(np.linalg.norm(p))
        depth = SPHERE_RADIUS_MM - r
        force = np.zeros(3)
        proxy = p
        if depth > 0 and r > 0:
            normal = p / r
            force = self.settings.stiffness_n_per_mm * depth * normal
            proxy = normal * SPHERE_RADIUS_MM
        magnitude = float(np.linalg.norm(force))
        clamped = magnitude > self.limits.max_force_n
        if clamped:
            force *= self.limits.max_force_n / magnitude
        half = self.settings.cube_half_A or 10.0
        return SpringOutput(force, proxy.copy(), p.copy(), (0,) if depth > 0 else (), depth > 0, clamped,
                            False, False, np.zeros(3), half)


class SpringBackend:
    FIELDS = ("probe_radius_A", "method", "stiffness_n_per_mm", "damping_n_s_per_m", "cube_half_A")

    def validate(self, settings, limits):
        checked = SpringSettings(**settings).validated(limits)
        return {k: getattr(checked, k) for k in self.FIELDS}

    def default_settings(self, limits):
        return self.validate({}, limits)

    def build(self, structure, limits, settings):
        return SpringEngine(structure, limits, SpringSettings(**settings).validated(limits))


def install() -> None:
    """Register `testarm` and make the spring engine the daemon's backend (this process only)."""
    import sasprobe.daemon.service as service
    import sasprobe.daemon.verify as verify
    from sasprobe.devices.registry import SCHEMES, DeviceScheme

    SCHEMES["testarm"] = DeviceScheme("tests.daemon_fakes:open_testarm", "test arm", "testarm")
    service.HapticBackend = SpringBackend
    verify.HapticBackend = SpringBackend


if __name__ == "__main__":  # python -m tests.daemon_fakes ARGS...: the sasprobe CLI with the fakes
    install()
    from sasprobe.cli import main

    sys.exit(main(sys.argv[1:]))
