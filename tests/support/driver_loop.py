"""A device driver driven straight, as the daemon's loop would drive it: reads until a state
comes, and a virtual wall (where the stylus comes to rest between the emulated hand's spring
and the wall)."""

from __future__ import annotations

import time

import numpy as np
from sasprobe.devices.base import DeviceFault


def read_until(dev, condition, timeout_s=5.0):
    """Read the device until `condition(state)` holds (a faulted read is tried again); the
    state. AssertionError after the timeout."""
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        try:
            state = dev.read()
            if condition(state):
                return state
        except DeviceFault:
            pass
        time.sleep(0.002)
    raise AssertionError("condition not reached in time")


WALL_X_MM, WALL_N_PER_MM = 10.0, 0.5  # a virtual wall beyond x = 10 mm, as stiff as the hand


def settle_against_a_wall(dev, timeout_s=30.0):
    """Tick (read, write the wall's force for that state) until the stylus has come to rest;
    its mean position over the last 100 reads. A late or failed read writes zero, as the
    daemon does."""
    xs: list[float] = []
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        try:
            state = dev.read()
        except DeviceFault:
            dev.write_force((0.0, 0.0, 0.0))
            continue
        x = float(state.position_mm[0])
        dev.write_force((-WALL_N_PER_MM * max(x - WALL_X_MM, 0.0), 0.0, 0.0))
        xs.append(x)
        if len(xs) >= 300 and np.ptp(xs[-100:]) < 0.05:
            return float(np.mean(xs[-100:]))
        time.sleep(0.001)
    raise AssertionError(f"never came to rest: the last reads span {np.ptp(xs[-100:]):.2f} mm")


def balance(hand_x_mm, hand_n_per_mm):
    """Where the hand's spring and the wall's balance."""
    return (hand_n_per_mm * hand_x_mm + WALL_N_PER_MM * WALL_X_MM) / (hand_n_per_mm + WALL_N_PER_MM)
