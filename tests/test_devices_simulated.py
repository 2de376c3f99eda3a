"""The simulated arm: registry, clock, physics against the analytic oscillator, faults, scripts."""

from __future__ import annotations

import dataclasses
import math
import time

import numpy as np
import pytest
from sasprobe.devices.base import PHANTOM_OMNI_LIMITS, DeviceFault, DeviceOpenError, HapticDevice
from sasprobe.devices.registry import open_device
from sasprobe.devices.simulated.arm import ArmModel, SimulatedDevice
from sasprobe.devices.simulated.hand_paths import SCRIPTS, HandPath
from sasprobe.devices.workspace.start import initial_mapping
from sasprobe.molecule import load_default

from tests.references.haptics import signed_distance

CRAMBIN = load_default()


def still(point=(0.0, 0.0, 0.0), jump_to=None, at: float = 0.0) -> HandPath:
    """A hand holding one point (optionally stepping to another at time `at`)."""
    if jump_to is None:
        return HandPath("still", [0.0, 100.0], [point, point])
    return HandPath("step", [0.0, at, at + 1e-9, 100.0], [point, point, jump_to, jump_to])


def test_registry_opens_every_script_and_rejects_unknown_ones():
    for name in SCRIPTS:
        device = open_device(f"sim:{name}", structure=CRAMBIN, rate_hz=500, colour="ignored")
        assert isinstance(device, HapticDevice)
        assert device.info.kind == "sim" and device.info.details["script"] == name
        limits = device.info.limits  # an Omni-class arm's, run up to 4 kHz
        assert limits == dataclasses.replace(PHANTOM_OMNI_LIMITS, max_rate_hz=4000.0)
    assert open_device("sim").hand_path.name == "scan"  # default script, default structure
    with pytest.raises(DeviceOpenError, match="unknown simulated-arm script"):
        open_device("sim:dance", structure=CRAMBIN)


@pytest.mark.parametrize("rate", [100, 250, 1000, 2000])
def test_clock_advances_one_period_per_force_write(rate):
    device = SimulatedDevice(still(), rate_hz=rate, start_ns=123)
    device.open()
    stamps = []
    for _ in range(5):
        stamps.append(device.read().t_ns)
        assert device.read().t_ns == stamps[-1]  # reading does not advance time
        device.write_force(np.zeros(3))
    assert np.all(np.diff(stamps) == round(1e9 / rate)) and stamps[0] == 123
    assert device.period_s / device.substeps <= 1e-4 + 1e-15  # finer than the control period


def test_the_clock_starts_on_the_hosts_monotonic_clock_a_period_before_the_first_reading():
    device = SimulatedDevice(still(), rate_hz=1000)
    device.open()
    device.write_force(np.zeros(3))  # a write before any reading still counts one period
    before = time.monotonic_ns()
    first = device.read().t_ns  # one period before the host's time at this read
    assert before <= first + 1_000_000 <= time.monotonic_ns()
    device.write_force(np.zeros(3))
    assert device.read().t_ns == first + 1_000_000


def test_free_motion_matches_the_analytic_damped_oscillator():
    arm = ArmModel(max_hand_force_n=math.inf)  # the linear model: a 5 mm step pulls with 1 N
    device = SimulatedDevice(still((0, 0, 0), jump_to=(5.0, 0, 0), at=0.0), rate_hz=1000, arm=arm)
    device.open()
    k = arm.hand_stiffness_n_per_mm * 1e3  # N/m
    b = arm.hand_damping_n_s_per_m + arm.arm_damping_n_s_per_m
    m = arm.mass_kg
    w0 = math.sqrt(k / m)
    zeta = b / (2 * math.sqrt(k * m))
    wd = w0 * math.sqrt(1 - zeta**2)
    worst = 0.0
    for tick in range(1, 301):
        device.write_force(np.zeros(3))
        t = tick * 1e-3
        # step response of m x'' + b x' + k x = k * 5 mm from rest at 0, plus the impulse
        # b_hand * 5 mm that the hand's damper (on the target's velocity) gives at the step
        v0 = arm.hand_damping_n_s_per_m * 5.0 / m  # mm/s
        decay = math.exp(-zeta * w0 * t)
        exact = (
            5.0 * (1 - decay * (math.cos(wd * t) + zeta * w0 / wd * math.sin(wd * t)))
            + v0 * decay * math.sin(wd * t) / wd
        )
        worst = max(worst, abs(device.read().position_mm[0] - exact))
    assert worst < 0.05  # mm, for a 5 mm step (semi-implicit Euler at 0.1 ms)


def test_held_force_displaces_the_hand_by_force_over_hand_stiffness_and_work_is_booked():
    device = SimulatedDevice(still(), rate_hz=1000)
    device.open()
    force = np.array([0.0, 0.3, -0.5])
    for _ in range(3000):
        device.write_force(force)
    x = device.read().position_mm
    assert np.allclose(x, force / ArmModel().hand_stiffness_n_per_mm, atol=1e-6)
    assert device.work_mj == pytest.approx(float(force @ x), rel=1e-9)  # sum of F.dx at constant F


def test_force_bookkeeping_clamp_nan_and_close():
    device = SimulatedDevice(still())
    device.open()
    device.write_force([10.0, 0.0, 0.0])
    assert np.linalg.norm(device.last_force_n) == pytest.approx(PHANTOM_OMNI_LIMITS.max_force_n)
    device.write_force([np.nan, 0.0, 0.0])
    assert device.nan_writes == 1 and np.array_equal(device.last_force_n, np.zeros(3))
    device.write_force([0.5, 0.0, 0.0])
    assert device.forces_written == 3 and device.last_force_n[0] == 0.5
    device.close()
    assert np.array_equal(device.last_force_n, np.zeros(3))
    with pytest.raises(DeviceFault):
        device.read()


def test_scheduled_and_injected_faults_then_recovery():
    device = SimulatedDevice(
        still(), faults=["raise@3+2", ("nan", 6, 1), "disconnect@8"], failed_reconnects=1
    )
    device.open()
    seen = []
    for _ in range(12):
        try:
            s = device.read()
            seen.append("nan" if not s.is_finite() else "ok")
        except DeviceFault:
            seen.append("fault")
        device.write_force(np.zeros(3))
    assert seen == ["ok"] * 3 + ["fault"] * 2 + ["ok", "nan", "ok"] + ["fault"] * 4
    with pytest.raises(DeviceFault):
        device.reconnect()  # the first attempt fails
    device.reconnect()
    assert device.read().is_finite()
    device.inject_fault("raise", 1)
    with pytest.raises(DeviceFault):
        device.read()
    assert device.read().is_finite()
    with pytest.raises(ValueError):
        device.inject_fault("fire")


def test_same_seed_same_session_different_seed_different_path():
    def trace(seed):
        device = open_device("sim:random", structure=CRAMBIN, seed=seed)
        device.open()
        out = []
        for k in range(2000):
            out.append(device.read().position_mm)
            device.write_force(np.array([0.0, 0.0, 0.1 * math.sin(k / 50)]))
        return np.array(out)

    a, b, c = trace(4), trace(4), trace(5)
    assert np.array_equal(a, b)
    assert np.abs(a - c).max() > 1.0


# Scripts that touch the surface, per cube: sweep moves in free space; orbit circles a whole
# molecule, and over a zoomed-in cube's surface it goes round above it.
TOUCHING = {None: set(SCRIPTS) - {"sweep", "orbit"}, "fit": set(SCRIPTS) - {"sweep"}}


@pytest.mark.parametrize("half", [None, "fit"], ids=["default cube", "fitted cube"])
@pytest.mark.parametrize("name", SCRIPTS)
def test_scripts_start_in_free_space_and_stay_in_the_drift_free_core(name, half):
    mapping = initial_mapping(CRAMBIN, PHANTOM_OMNI_LIMITS, half)
    device = open_device(f"sim:{name}", structure=CRAMBIN, seed=2, cube_half_A=half)
    script = device.hand_path
    start = np.array(mapping.to_molecule(*script.start))
    assert signed_distance(start, CRAMBIN.positions, CRAMBIN.expanded_radii(1.4))[0] > 1.0
    targets = np.array([script.target(t) for t in np.linspace(0, script.duration_s, 2000)])
    center = np.array(mapping.workspace_center_mm)
    assert np.all(np.abs(targets - center) <= mapping.core_half_mm)
    goals = np.array([mapping.to_molecule(*p) for p in targets])
    touching = (signed_distance(goals, CRAMBIN.positions, CRAMBIN.expanded_radii(1.4)) < 0).mean()
    if name in TOUCHING[half]:
        assert touching > 0.2
    assert np.allclose(script.target(script.duration_s * 3 + 0.25), script.target(0.25))  # loops


def test_dive_targets_a_groove_between_two_surface_atoms():
    script = open_device("sim:dive", structure=CRAMBIN).hand_path
    i, j = script.info["atoms"]
    crease = np.array(script.info["crease_A"])
    radii = CRAMBIN.expanded_radii(1.4)
    on_both = [abs(np.linalg.norm(crease - CRAMBIN.positions[a]) - radii[a]) for a in (i, j)]
    assert max(on_both) < 1e-9
    assert (
        signed_distance(crease, CRAMBIN.positions, radii)[0] > -1e-9
    )  # on the surface, not buried
