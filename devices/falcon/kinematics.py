"""Stamper kinematics of the Falcon's delta: encoders ↔ grip position, force → motor commands.

The equations are Stamper's (R. E. Stamper, PhD thesis, U. Maryland 1997) with the Falcon's
geometry as libnifalcon publishes it (FalconGeometry.h, FalconKinematicStamper.cpp).
Leg i has its own frame (u, v, w): the world turned by −φ_i about z, then moved by
(−r, −s, 0). Its thigh (length a) turns by θ1 about the v axis; the shin parallelogram
(side b, joint bars d and e) reaches the effector's joint, at (c, f, 0) from the
effector centre in that frame. With C = (u + c, v + f, w):

    θ3 = acos(C_v / b),   D = d + e + b sin θ3,
    (C_u − a cos θ1)² + (C_w − a sin θ1)² = D²,
    θ2 = atan2(C_w − a sin θ1, C_u − a cos θ1).

Inverse kinematics solves the middle line as C_u cos θ1 + C_w sin θ1 = k on the branch
libnifalcon takes (its T1b root: the knee outward). The joint rates are Stamper's:
∂θ1/∂p = n / (a sin θ3 sin(θ2 − θ1)), n the shin's direction
(sin θ3 cos θ2, cos θ3, sin θ3 sin θ2) turned back into the world. libnifalcon's copy of
the z entry reads sin θ2 · sin θ2; differentiating the constraint (and libnifalcon's own
earlier Ouellet implementation, boneyard/ouellet_kinematics/JacobianMatrix.cpp) gives
sin θ2 · sin θ3, which we use: at the centre libnifalcon's z torques are 1.34 × ours.

Forward kinematics is Newton's method on the inverse, as libnifalcon does, but run to
1e-12 rad instead of its 0.01 rad stop, from the last pose. Torques are τ = Jᵀ F with
J = ∂p/∂θ1 (virtual work); the command is −10000 τ, truncated like libnifalcon's int
conversion, all three scaled by one factor if any exceeds ±4096 so the direction survives.

Units: metres and radians inside; the driver's frame is millimetres from the workspace
centre (`to_device_mm`, `from_device_mm`), same axes.
"""

from __future__ import annotations

import numpy as np

from sasprobe.devices.falcon import models as M
from sasprobe.devices.kinematics import KinematicsError, scale_to_limit

_COS, _SIN = np.cos(M.LEG_AZIMUTH_RAD), np.sin(M.LEG_AZIMUTH_RAD)
_BASE = np.array([M.BASE_U_M, M.BASE_V_M])
_JOINT = np.array([M.EFFECTOR_U_M, M.EFFECTOR_V_M])
_BARS = M.EFFECTOR_JOINT_M + M.KNEE_JOINT_M  # d + e


def thigh_angles(counts) -> np.ndarray:
    """Encoder counts → thigh angles θ1 (rad), valid once the Falcon is homed."""
    return M.THIGH_AT_ZERO_COUNT_RAD + np.asarray(counts, dtype=float) * M.THIGH_RAD_PER_COUNT


def to_device_mm(p_m) -> np.ndarray:
    return (np.asarray(p_m, dtype=float) - M.WORKSPACE_CENTRE_M) * 1000.0


def from_device_mm(p_mm) -> np.ndarray:
    return np.asarray(p_mm, dtype=float) / 1000.0 + M.WORKSPACE_CENTRE_M


def leg_joint_points(p_m) -> np.ndarray:
    """C for each leg: rows (C_u, C_v, C_w), metres."""
    x, y, z = np.asarray(p_m, dtype=float)
    u = _COS * x + _SIN * y - _BASE[0] + _JOINT[0]
    v = -_SIN * x + _COS * y - _BASE[1] + _JOINT[1]
    return np.stack([u, v, np.full(3, z)], axis=1)


def inverse(p_m) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Position (m, libnifalcon frame) → (θ1, θ2, θ3) per leg, rad."""
    c = leg_joint_points(p_m)
    cos3 = c[:, 1] / M.SHIN_M
    if np.any(np.abs(cos3) > 1.0):
        raise KinematicsError("position out of the Falcon's reach (shin)")
    theta3 = np.arccos(cos3)
    reach = _BARS + M.SHIN_M * np.sin(theta3)  # D
    rho = np.hypot(c[:, 0], c[:, 2])
    k = (rho ** 2 + M.THIGH_M ** 2 - reach ** 2) / (2.0 * M.THIGH_M)
    if np.any(np.abs(k) > rho):
        raise KinematicsError("position out of the Falcon's reach (thigh)")
    theta1 = np.arctan2(c[:, 2], c[:, 0]) - np.arccos(k / rho)
    theta2 = np.arctan2(c[:, 2] - M.THIGH_M * np.sin(theta1), c[:, 0] - M.THIGH_M * np.cos(theta1))
    return theta1, theta2, theta3


def joint_rates(theta1, theta2, theta3) -> np.ndarray:
    """∂θ1_i/∂p (rad/m), one row per leg: Stamper's Jacobian."""
    den = M.THIGH_M * np.sin(theta3) * np.sin(theta2 - theta1)
    if np.any(np.abs(den) < 1e-9):
        raise KinematicsError("the Falcon is at a singular pose")
    n_u, n_v, n_w = np.sin(theta3) * np.cos(theta2), np.cos(theta3), np.sin(theta3) * np.sin(theta2)
    return np.stack([_COS * n_u - _SIN * n_v, _SIN * n_u + _COS * n_v, n_w], axis=1) / den[:, None]


def jacobian(p_m) -> np.ndarray:
    """J = ∂p/∂θ1 (m/rad) at a position."""
    return np.linalg.inv(joint_rates(*inverse(p_m)))


def forward(theta1, guess_m=None, tolerance_rad: float = 1e-12) -> np.ndarray:
    """Thigh angles → position (m): Newton on `inverse`, halving steps that do not help."""
    target = np.asarray(theta1, dtype=float)
    p = (M.WORKSPACE_CENTRE_M if guess_m is None else np.asarray(guess_m, dtype=float)).copy()
    angles = inverse(p)
    error = target - angles[0]
    for _ in range(50):
        if np.max(np.abs(error)) < tolerance_rad:
            return p
        step = np.linalg.solve(joint_rates(*angles), error)
        for _halving in range(30):
            try:
                candidate = p + step
                new_angles = inverse(candidate)
                new_error = target - new_angles[0]
                if np.linalg.norm(new_error) < np.linalg.norm(error):
                    break
            except KinematicsError:
                pass
            step = step / 2.0
        else:
            break
        p, angles, error = candidate, new_angles, new_error
    if np.max(np.abs(error)) < 1e-9:
        return p
    raise KinematicsError("the Falcon's encoders match no reachable position")


def motor_commands(p_m, force_n) -> list[int]:
    """Force (N, same axes) at a position → the three signed motor commands."""
    torque = jacobian(p_m).T @ np.asarray(force_n, dtype=float)
    counts, _factor = scale_to_limit(M.MOTOR_COUNTS_PER_NM * torque, M.MOTOR_COMMAND_LIMIT)
    return [int(c) for c in counts]  # int() truncates toward zero, as libnifalcon's conversion
