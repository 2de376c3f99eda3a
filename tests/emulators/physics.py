"""The emulated hand, the stylus it holds, and the statics of an emulated linkage.

A stylus tip of mass m is held by a hand: a spring-damper pulls it toward where the
hand is, and the device's motors add their force. The hand moves toward its target at
a finite speed, as a hand does. Units: mm, mm/s, N, s. Mechanisms are described by
their forward kinematics alone: the joint angles that put the tip where the stylus is
come from Newton's method started at the previous angles, and the tip force of joint
torques from the Jacobian's finite differences (τ = Jᵀ·F solved for F).
"""

from __future__ import annotations

import collections
import threading
import time
from dataclasses import dataclass

import numpy as np

SUBSTEP_S = 0.00025
MAX_GAP_S = 1.0  # longer gaps (a suspended process) are integrated as this long


class MovableHand:
    """A hand whose target the test sets (`hand.target = (x, y, z)`, mm); it gets there at
    `speed_mm_s`. `position` is where it is now. (Any function of time in seconds that
    returns a position in mm is a hand too.)"""

    def __init__(self, target=(0.0, 0.0, 0.0), speed_mm_s: float = 400.0):
        self.position = np.asarray(target, dtype=float).copy()
        self.target = tuple(target)
        self.speed_mm_s = speed_mm_s
        self._last: float | None = None
        self._lock = threading.Lock()

    def place(self, at) -> None:
        """Put the hand (and its target) somewhere at once."""
        with self._lock:
            self.position = np.asarray(at, dtype=float).copy()
            self.target = tuple(self.position)

    def __call__(self, now: float) -> np.ndarray:
        with self._lock:
            if self._last is not None:
                step = np.asarray(self.target, dtype=float) - self.position
                distance = float(np.linalg.norm(step))
                reach = self.speed_mm_s * max(now - self._last, 0.0)
                self.position = self.position + (
                    step if distance <= reach else step * (reach / distance)
                )
            self._last = now
            return self.position.copy()


class HeldStylus:
    def __init__(
        self,
        start_mm,
        hand: MovableHand | None = None,
        *,
        mass_kg: float = 0.1,
        hand_stiffness_n_per_mm: float = 0.5,
        damping_n_s_per_m: float | None = None,
        planar_axis: int | None = None,
    ):
        self.position = np.asarray(start_mm, dtype=float).copy()
        self.velocity = np.zeros(3)
        self.mass_kg = mass_kg
        self.hand_k = hand_stiffness_n_per_mm
        if damping_n_s_per_m is None:  # a hand holds firmly: critically damped
            damping_n_s_per_m = 2.0 * (hand_stiffness_n_per_mm * 1000.0 * mass_kg) ** 0.5
        self.damping = damping_n_s_per_m / 1000.0  # N per (mm/s)
        self.hand = hand or MovableHand(start_mm)
        self.planar_axis = (
            planar_axis  # a pad that holds the tip in a plane: this coordinate stays put
        )
        self._plane = None if planar_axis is None else float(self.position[planar_axis])
        self.t0 = (
            time.monotonic()
        )  # a hand is a function of the time since the stylus was picked up
        self._hand_mm = np.asarray(
            self.hand(0.0), dtype=float
        )  # where the hand was at the last advance
        self._last: float | None = None
        self.lock = threading.Lock()

    def advance(self, motor_force_n) -> np.ndarray:
        """Advance to now under the motor force (held constant since the last call)."""
        now = time.monotonic()
        with self.lock:
            dt = 0.0 if self._last is None else min(now - self._last, MAX_GAP_S)
            self._last = now
            start = np.asarray(self.hand(now - dt - self.t0), dtype=float)
            end = np.asarray(self.hand(now - self.t0), dtype=float)
            force = np.asarray(motor_force_n, dtype=float)
            substeps = max(1, int(np.ceil(dt / SUBSTEP_S)))
            h = dt / substeps
            for i in range(substeps):
                target = start + (end - start) * ((i + 1) / substeps)
                total = (
                    force + self.hand_k * (target - self.position) - self.damping * self.velocity
                )
                self.velocity = self.velocity + h * total / self.mass_kg * 1000.0
                self.position = self.position + h * self.velocity
                if self.planar_axis is not None:
                    self.velocity[self.planar_axis] = 0.0
                    self.position[self.planar_axis] = self._plane
            self._hand_mm = end
            return self.position.copy()

    def now(self) -> np.ndarray:
        with self.lock:
            return self.position.copy()

    def held(self) -> tuple[np.ndarray, np.ndarray]:
        """(stylus, hand) at the last advance, mm."""
        with self.lock:
            return self.position.copy(), self._hand_mm.copy()


def numeric_jacobian(fk, q, step: float = 1e-6) -> np.ndarray:
    q = np.asarray(q, dtype=float)
    columns = []
    for i in range(len(q)):
        dq = np.zeros_like(q)
        dq[i] = step
        columns.append((np.asarray(fk(q + dq)) - np.asarray(fk(q - dq))) / (2.0 * step))
    return np.stack(columns, axis=1)


def follow(fk, q, target, tolerance: float = 1e-7, iterations: int = 30) -> np.ndarray:
    """Joint angles near `q` whose forward kinematics reach `target` (Newton's method)."""
    q = np.asarray(q, dtype=float).copy()
    target = np.asarray(target, dtype=float)
    for _ in range(iterations):
        error = target - np.asarray(fk(q))
        if np.max(np.abs(error)) < tolerance:
            return q
        step = np.linalg.lstsq(numeric_jacobian(fk, q), error, rcond=None)[0]
        q = q + np.clip(step, -0.2, 0.2)
    raise ValueError(f"the linkage cannot reach {np.round(target, 2).tolist()}")


def tip_force(fk, q, joint_torques) -> np.ndarray:
    """The tip force joint torques make, for a forward kinematics in the units of the force's
    lever (a fk in metres and torques in N·m give N)."""
    return np.linalg.lstsq(
        numeric_jacobian(fk, q).T, np.asarray(joint_torques, dtype=float), rcond=None
    )[0]


@dataclass(frozen=True)
class Sample:
    """What the motors did from `t_ns` (monotonic) on: the force on the stylus (N), and
    where the stylus and the hand holding it were (mm)."""

    t_ns: int
    force_n: np.ndarray
    stylus_mm: np.ndarray
    hand_mm: np.ndarray


class ArmUnderStylus:
    """The links of a serial board's arm under the held stylus (for PtySerialDevice boards):
    every move the links follow the stylus (`_follow`, Newton's method from where they
    were), the Jacobian is taken there (`_jacobian_now`), and the motors' force
    (`motor_force`) is refreshed; it acts on the stylus until the next refresh, and
    `samples` records it. The board calls `_start_arm()` once its links and stylus are in
    place."""

    def _start_arm(self) -> None:
        self.max_force_n = 0.0
        self.samples: collections.deque[Sample] = collections.deque(maxlen=20000)
        self._force = np.zeros(3)
        self._jacobian = self._jacobian_now()
        self._moved_at = 0.0

    def _follow(self, where_mm: np.ndarray) -> None:
        raise NotImplementedError

    def _jacobian_now(self) -> np.ndarray:
        raise NotImplementedError

    def motor_force(self) -> np.ndarray:
        raise NotImplementedError

    def _move(self) -> None:
        """The links follow the stylus (the hand and the motors move it)."""
        self.stylus.advance(self._force)
        try:
            self._follow(self.stylus.now())
        except ValueError:
            pass  # beyond the links' reach: they stay where they could go
        self._jacobian = self._jacobian_now()
        self._moved_at = time.monotonic()
        self._refresh_force()

    def _refresh_force(self) -> None:
        self.stylus.advance(self._force)  # the old force acted until now
        self._force = self.motor_force()
        self.max_force_n = max(self.max_force_n, float(np.linalg.norm(self._force)))
        stylus_mm, hand_mm = self.stylus.held()
        self.samples.append(Sample(time.monotonic_ns(), self._force.copy(), stylus_mm, hand_mm))
