"""Safety guard: watchdog reasons, ramp on device time, clamp, recovery."""

from __future__ import annotations

import math

import numpy as np
import pytest
from sasprobe.daemon.haptics.safety import SafetyGuard
from sasprobe.devices.base import PHANTOM_OMNI_LIMITS, DeviceState


def state(t_s: float, calibrated: bool = True, position=(0.0, 0.0, 0.0)) -> DeviceState:
    return DeviceState(
        t_ns=int(t_s * 1e9), position_mm=np.array(position, dtype=float), calibrated=calibrated
    )


def run(guard, force, st, error=None, late=0.0, ramp_again=True):
    return guard.filter(force, st, guard.check(st, error, late), ramp_again)


def test_ramp_over_the_first_second_of_device_time():
    guard = SafetyGuard(PHANTOM_OMNI_LIMITS)
    f = np.array([0.0, 0.0, 2.0])
    ramps = [run(guard, f, state(10 + t)).force_n[2] / 2.0 for t in (0.0, 0.25, 0.5, 1.0, 3.0)]
    assert ramps == pytest.approx([0.0, 0.25, 0.5, 1.0, 1.0])


def test_clamp_keeps_direction():
    guard = SafetyGuard(PHANTOM_OMNI_LIMITS, ramp_s=0)
    r = run(guard, np.array([30.0, 40.0, 0.0]), state(0))
    assert r.clamped and np.linalg.norm(r.force_n) == pytest.approx(PHANTOM_OMNI_LIMITS.max_force_n)
    assert r.force_n[0] / r.force_n[1] == pytest.approx(0.75)


@pytest.mark.parametrize(
    "force, st, error, late, fragment",
    [
        ([0, 0, 1], None, "read timed out", 0.0, "read failed"),
        ([0, 0, 1], state(0, position=(math.nan, 0, 0)), None, 0.0, "non-finite device state"),
        ([0, 0, 1], state(0), None, 3.5, "periods late"),
        ([0, math.inf, 1], state(0), None, 0.0, "non-finite force"),
        (None, state(0), None, 0.0, "non-finite force"),
    ],
)
def test_watchdog_zeroes_force(force, st, error, late, fragment):
    guard = SafetyGuard(PHANTOM_OMNI_LIMITS, ramp_s=0)
    r = run(guard, None if force is None else np.array(force, dtype=float), st, error, late)
    assert r.fault and fragment in r.reason
    assert r.force_n.tolist() == [0.0, 0.0, 0.0]
    assert guard.faulted


def test_three_periods_late_is_still_fine():
    guard = SafetyGuard(PHANTOM_OMNI_LIMITS, ramp_s=0)
    assert not run(guard, np.array([0.0, 0.0, 1.0]), state(0), late=3.0).fault


def test_recovery_ramps_again_after_device_faults_but_not_after_a_late_tick():
    guard = SafetyGuard(PHANTOM_OMNI_LIMITS)
    f = np.array([1.0, 0.0, 0.0])
    assert run(guard, f, state(0.0)).ramp == 0.0
    assert run(guard, f, state(2.0)).force_n[0] == 1.0  # fully ramped
    assert run(guard, f, state(2.001), late=5, ramp_again=False).fault
    r = run(guard, f, state(2.002))
    assert r.recovered and r.force_n[0] == 1.0  # a late tick does not restart the ramp
    assert run(guard, f, None, error="link lost").fault
    r = run(guard, f, state(2.5))
    assert r.recovered and r.force_n[0] == 0.0 and r.ramp == 0.0
    assert run(guard, f, state(3.0)).force_n[0] == pytest.approx(0.5)
    assert guard.faults == 2


def test_uncalibrated_device_gets_no_force_and_restarts_the_ramp():
    guard = SafetyGuard(PHANTOM_OMNI_LIMITS)
    f = np.array([1.0, 0.0, 0.0])
    run(guard, f, state(0.0))
    assert run(guard, f, state(5.0, calibrated=False)).force_n[0] == 0.0
    assert run(guard, f, state(5.1)).force_n[0] == 0.0
    assert run(guard, f, state(5.6)).force_n[0] == pytest.approx(0.5)


class _TouchingEngine:
    """An engine that always touches atom 7 (the pipeline's view of an engine)."""

    def step(self, st):
        from types import SimpleNamespace

        return SimpleNamespace(
            force_n=np.array([0.0, 0.0, 0.1]),
            fault=False,
            contact=True,
            drifting=False,
            clamped=False,
            clutched=False,
            touched_atoms=(7,),
            proxy_A=np.ones(3),
            goal_A=np.ones(3),
            cube_center_A=np.zeros(3),
            cube_half_A=5.0,
        )


def test_a_failed_read_repeats_the_device_time_and_touches_nothing():
    from sasprobe.daemon.haptics.pipeline import HapticPipeline
    from sasprobe.protocol.pose import FLAG_CONTACT, FLAG_FAULT

    pipeline = HapticPipeline(_TouchingEngine(), SafetyGuard(PHANTOM_OMNI_LIMITS))
    good = state(5.0)
    touching = pipeline.pose(1, good, pipeline.step(good, None, 0.0), 6_000_000_000)
    assert (
        touching.touched_atom == 7
        and touching.flags & FLAG_CONTACT
        and touching.device_t_ns == good.t_ns
    )
    failed = pipeline.pose(2, None, pipeline.step(None, "read timed out", 0.0), 6_001_000_000)
    assert (
        failed.flags & FLAG_FAULT and not failed.flags & FLAG_CONTACT and failed.touched_atom == -1
    )
    assert failed.device_t_ns == good.t_ns and np.array_equal(failed.proxy_A, touching.proxy_A)
