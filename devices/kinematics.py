"""Arm kinematics: joint angles ↔ tip position, Jacobians, force → joint torques.

What several drivers share, and the Novint Falcon's rotary delta: forward kinematics
is solved numerically (Newton on the inverse kinematics, step halving when the residual
grows), the force mapping is τ = Jᵀ·F with one common scale factor when any torque
exceeds the limit (§3). The serial arms keep their mechanisms in their own packages
(`woodenhaptics/kinematics.py`, `haply/kinematics.py`).

Conventions: `J[:, i] = ∂p/∂q_i` (mm/rad). By virtual work F·dp = τ·dq, so the joint
torques that render a tip force F (N) are τ = Jᵀ·F; with J in mm/rad that is N·mm,
hence the 1/1000 in `joint_torques`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np


class KinematicsError(ValueError):
    """A pose outside the mechanism's reach, or a singular configuration."""


def joint_torques(jacobian_mm: np.ndarray, force_n: np.ndarray) -> np.ndarray:
    """τ = Jᵀ·F in N·m for a Jacobian in mm/rad and a force in N."""
    return jacobian_mm.T @ np.asarray(force_n, dtype=float) / 1000.0


def scale_to_limit(torques: np.ndarray, limit: float | np.ndarray) -> tuple[np.ndarray, float]:
    """Scale all torques by one factor so none exceeds its limit: the force direction survives.

    Returns (scaled torques, factor ≤ 1). Clipping each joint on its own would bend the
    rendered force away from the commanded direction.
    """
    torques = np.asarray(torques, dtype=float)
    ratio = np.max(np.abs(torques) / np.asarray(limit, dtype=float))
    if not np.isfinite(ratio):
        return np.zeros_like(torques), 0.0
    if ratio <= 1.0:
        return torques, 1.0
    return torques / ratio, 1.0 / ratio


def tip_force(jacobian_mm: np.ndarray, torques_nm: np.ndarray) -> np.ndarray:
    """The tip force (N) that joint torques (N·m) produce: solves Jᵀ·F = τ (square J only)."""
    return np.linalg.solve(jacobian_mm.T, np.asarray(torques_nm, dtype=float) * 1000.0)


# --------------------------------------------------------------------------------------
# Novint Falcon: rotary delta
# --------------------------------------------------------------------------------------

@dataclass(frozen=True)
class DeltaGeometry:
    """A rotary delta fitted with the Falcon's published dimensions (research notes §3).

    Our model is the textbook rotary delta: leg i's motor sits at radius `base_radius`
    from the centre, its thigh (length `thigh`) swings in the plane spanned by the leg's
    radial direction and the device's Z axis, and a parallelogram (length `shin`) joins
    the knee to the end-effector platform at radius `platform_radius`; the grip point
    sits `grip_offset` along Z from the platform centre. The parallelogram widths of the
    published constant set (c, d, e) shift both ends of a shin equally and do not enter
    the point kinematics of this model. It is not a transcription of Stamper's
    equations: expect to calibrate offsets on real hardware.
    """

    thigh: float = 60.0  # a
    shin: float = 102.5  # b
    base_radius: float = 40.0  # r
    platform_radius: float = 23.09  # |s|
    grip_offset: float = -25.0  # f, along Z
    leg_angles_deg: tuple[float, float, float] = (90.0, -30.0, -150.0)


# With all thighs at 16.7° the grip sits at the centre of the largest cube we found in
# this model's reach with a well-conditioned Jacobian: ±40 mm, condition number < 4
# (CHAI3D quotes a 0.04 m workspace radius for the Falcon).
DELTA_CENTRE_ANGLE = math.radians(16.7)


class DeltaArm:
    """Falcon delta: numeric FK (Newton on the IK), Jacobian, torque mapping.

    Device frame: Z toward the user (the grip side), Y up, X right; positions are
    reported relative to `centre_mm`, the grip position with all thighs at `centre_angle`.
    """

    def __init__(self, geometry: DeltaGeometry | None = None, centre_angle: float = DELTA_CENTRE_ANGLE):
        self.g = geometry or DeltaGeometry()
        phi = np.radians(self.g.leg_angles_deg)
        self._u = np.stack([np.cos(phi), np.sin(phi), np.zeros(3)], axis=1)  # radial unit vectors
        self._z = np.array([0.0, 0.0, 1.0])
        self._grip = np.array([0.0, 0.0, self.g.grip_offset])
        self.centre_mm = self._absolute_fk(np.full(3, centre_angle))

    def _knee(self, theta: np.ndarray) -> np.ndarray:
        g = self.g
        return (g.base_radius + g.thigh * np.cos(theta))[:, None] * self._u + (g.thigh * np.sin(theta))[:, None] * self._z

    def _dknee(self, theta: np.ndarray) -> np.ndarray:
        g = self.g
        return (-g.thigh * np.sin(theta))[:, None] * self._u + (g.thigh * np.cos(theta))[:, None] * self._z

    def _platform_joints(self, p_abs: np.ndarray) -> np.ndarray:
        return (p_abs - self._grip)[None, :] + self.g.platform_radius * self._u

    def _absolute_ik(self, p_abs: np.ndarray) -> np.ndarray:
        g = self.g
        # Leg i: |P_i − K_i(θ)|² = b². With q = P_i − r·u_i, in the leg plane (qu, qz):
        # qu cos θ + qz sin θ = (|q|² + a² − b²) / 2a.
        q = self._platform_joints(p_abs) - g.base_radius * self._u
        qu = np.einsum("ij,ij->i", q, self._u)
        qz = q[:, 2]
        k = (np.einsum("ij,ij->i", q, q) + g.thigh ** 2 - g.shin ** 2) / (2.0 * g.thigh)
        rho = np.hypot(qu, qz)
        if np.any(np.abs(k) > rho):
            raise KinematicsError("position out of the Falcon's reach")
        # the knee-out branch: the thigh points away from the centre line
        return np.arctan2(qz, qu) - np.arccos(k / rho)

    def _symmetric_guess(self, theta: np.ndarray) -> np.ndarray:
        """The exact answer when all thighs share one angle: a start for Newton."""
        g, t = self.g, float(np.mean(theta))
        radial = g.base_radius + g.thigh * math.cos(t) - g.platform_radius
        return np.array([0.0, 0.0, g.grip_offset + g.thigh * math.sin(t) + math.sqrt(max(g.shin ** 2 - radial ** 2, 0.0))])

    def _absolute_fk(self, theta: np.ndarray, guess: np.ndarray | None = None) -> np.ndarray:
        p = (self._symmetric_guess(theta) if guess is None else guess).astype(float).copy()
        residual = self._ik_residual(p, theta)
        for _ in range(30):
            if np.max(np.abs(residual)) < 1e-12:
                return p
            step = np.linalg.solve(self._ik_jacobian(p), residual)
            for _halving in range(20):  # halve the step until the residual shrinks
                candidate = p - step
                try:
                    new_residual = self._ik_residual(candidate, theta)
                except KinematicsError:
                    new_residual = None
                if new_residual is not None and np.linalg.norm(new_residual) < np.linalg.norm(residual):
                    break
                step = step / 2.0
            else:
                break
            p, residual = candidate, new_residual
        if np.max(np.abs(residual)) < 1e-9:
            return p
        raise KinematicsError("Falcon forward kinematics did not converge")

    def _ik_residual(self, p_abs: np.ndarray, theta: np.ndarray) -> np.ndarray:
        d = self._absolute_ik(p_abs) - theta
        return (d + np.pi) % (2.0 * np.pi) - np.pi

    def _ik_jacobian(self, p_abs: np.ndarray) -> np.ndarray:
        """∂θ/∂p by implicit differentiation of |P_i − K_i(θ_i)|² = b²."""
        theta = self._absolute_ik(p_abs)
        w = self._platform_joints(p_abs) - self._knee(theta)  # (3, 3): shin vectors
        dk = self._dknee(theta)
        denom = np.einsum("ij,ij->i", w, dk)
        if np.any(np.abs(denom) < 1e-9):
            raise KinematicsError("Falcon at a singular configuration")
        return w / denom[:, None]

    # public API, device frame relative to the workspace centre -----------------------
    def inverse(self, p) -> np.ndarray:
        """Grip position (mm, relative to the centre) → thigh angles (rad)."""
        return self._absolute_ik(np.asarray(p, dtype=float) + self.centre_mm)

    def forward(self, theta, guess=None) -> np.ndarray:
        """Thigh angles (rad) → grip position (mm, relative to the centre); numeric."""
        g = None if guess is None else np.asarray(guess, dtype=float) + self.centre_mm
        return self._absolute_fk(np.asarray(theta, dtype=float), g) - self.centre_mm

    def jacobian(self, theta, p=None) -> np.ndarray:
        """∂p/∂θ (mm/rad), the inverse of the IK Jacobian at the pose."""
        if p is None:
            p = self.forward(theta)
        return np.linalg.inv(self._ik_jacobian(np.asarray(p, dtype=float) + self.centre_mm))

    def torques(self, theta, force_n, limit_nm: float, p=None) -> tuple[np.ndarray, float]:
        """τ = Jᵀ·F (N·m), scaled by one factor if any exceeds `limit_nm`."""
        return scale_to_limit(joint_torques(self.jacobian(theta, p), force_n), limit_nm)
