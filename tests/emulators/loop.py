"""A minimal host control loop for closed-loop driver tests (the daemon's job, in miniature)."""

from __future__ import annotations

import time

import numpy as np

from sasprobe.devices.base import DeviceState, HapticDevice


def run(device: HapticDevice, seconds: float, force_of=None, rate_hz: float = 1000.0) -> list[DeviceState]:
    """read → force_of(state) → write_force, paced at `rate_hz`; returns every state read."""
    states = []
    period = 1.0 / rate_hz
    start = next_tick = time.monotonic()
    while time.monotonic() - start < seconds:
        state = device.read()
        states.append(state)
        device.write_force(np.zeros(3) if force_of is None else force_of(state))
        next_tick += period
        delay = next_tick - time.monotonic()
        if delay > 0:
            time.sleep(delay)
    return states


def until(device: HapticDevice, condition, timeout_s: float = 10.0, force_of=None) -> DeviceState:
    """Run the loop until `condition(state)` holds; AssertionError after `timeout_s`."""
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        state = device.read()
        if condition(state):
            return state
        device.write_force(np.zeros(3) if force_of is None else force_of(state))
        time.sleep(0.0005)
    raise AssertionError("condition not reached in time")


def wall(axis: int, at_mm: float, stiffness_n_per_mm: float):
    """A virtual wall: pushes back along -axis once the tip passes `at_mm`."""
    def force_of(state: DeviceState) -> np.ndarray:
        f = np.zeros(3)
        depth = state.position_mm[axis] - at_mm
        if depth > 0:
            f[axis] = -stiffness_n_per_mm * depth
        return f
    return force_of
