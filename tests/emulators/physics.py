"""The emulated hand and stylus: simple physics so closed-loop tests have something to push.

A stylus tip of mass m is held by a hand: a spring-damper pulls it toward where the hand
wants it (`hand(t)`, mm), and the device's motors add their force. Units: mm, mm/s, N.
"""

from __future__ import annotations

import threading
import time

import numpy as np


class HeldStylus:
    def __init__(self, start_mm=(0.0, 0.0, 0.0), *, mass_kg: float = 0.1, hand_stiffness_n_per_mm: float = 0.5,
                 damping_n_s_per_m: float = 4.0, hand=None, max_step_s: float = 0.005):
        self.position = np.asarray(start_mm, dtype=float).copy()
        self.velocity = np.zeros(3)
        self.mass_kg = mass_kg
        self.hand_k = hand_stiffness_n_per_mm
        self.damping = damping_n_s_per_m / 1000.0  # N per (mm/s)
        self.hand = hand or (lambda t: start_mm)
        self.max_step_s = max_step_s
        self.t0 = time.monotonic()
        self._last = None
        self.lock = threading.Lock()

    def hand_target(self) -> np.ndarray:
        return np.asarray(self.hand(time.monotonic() - self.t0), dtype=float)

    def advance(self, motor_force_n) -> np.ndarray:
        """Advance to now under the given motor force (held constant since the last call)."""
        now = time.monotonic()
        with self.lock:
            dt = 0.0 if self._last is None else min(now - self._last, self.max_step_s)
            self._last = now
            target = self.hand_target()
            force = np.asarray(motor_force_n, dtype=float)
            substeps = max(1, int(np.ceil(dt / 0.0005)))
            h = dt / substeps
            for _ in range(substeps):
                total = force + self.hand_k * (target - self.position) - self.damping * self.velocity
                self.velocity = self.velocity + h * total / self.mass_kg * 1000.0
                self.position = self.position + h * self.velocity
            return self.position.copy()


class MovableHand:
    """A hand whose target the test moves: `hand.target = (x, y, z)`."""

    def __init__(self, target=(0.0, 0.0, 0.0)):
        self.target = tuple(target)

    def __call__(self, t: float):
        return self.target
