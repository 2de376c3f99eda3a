"""A minimal host control loop for closed-loop driver tests (the daemon's job, in miniature).

A harness on the host side, not an emulator: it drives the drivers under test, so it
lives outside tests/emulators/ (whose modules import nothing from sasprobe).
"""

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


def pull_the_cable(device: HapticDevice, unplug, replug, command=(0.0, 0.0, 0.0)) -> DeviceState:
    """Unplug: the next exchange faults at once (no read timeout to wait out), reconnecting
    fails while the cable is out; replug: reconnect works. Returns the first state after."""
    import pytest

    from sasprobe.devices.base import DeviceFault

    unplug()
    t0 = time.monotonic()
    with pytest.raises(DeviceFault):
        device.write_force(command)
        device.read()
    assert time.monotonic() - t0 < 1.0  # generous: the fault comes from the first transfer
    with pytest.raises(DeviceFault, match="still unavailable"):
        device.reconnect()
    replug()
    device.reconnect()
    return device.read()
