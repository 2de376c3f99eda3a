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
centre (`to_device_mm`, `from_device_mm`), same axes. Written in scalar math rather
than numpy: on 3-vectors numpy's call overhead made one forward solve cost ~160 µs of
the 1 ms tick; this way it is a few tens.
"""

from __future__ import annotations

import math

import numpy as np
from sasprobe.devices.falcon import models as M
from sasprobe.devices.kinematics import KinematicsError, scale_to_limit

_LEGS = [(math.cos(phi), math.sin(phi)) for phi in M.LEG_AZIMUTH_RAD]
_BARS = M.EFFECTOR_JOINT_M + M.KNEE_JOINT_M  # d + e
_A, _B = M.THIGH_M, M.SHIN_M


def thigh_angles(counts) -> np.ndarray:
    """Encoder counts → thigh angles θ1 (rad), valid once the Falcon is homed."""
    return M.THIGH_AT_ZERO_COUNT_RAD + np.asarray(counts, dtype=float) * M.THIGH_RAD_PER_COUNT


def to_device_mm(p_m) -> np.ndarray:
    return (np.asarray(p_m, dtype=float) - M.WORKSPACE_CENTRE_M) * 1000.0


def from_device_mm(p_mm) -> np.ndarray:
    return np.asarray(p_mm, dtype=float) / 1000.0 + M.WORKSPACE_CENTRE_M


def inverse(p_m) -> tuple[list[float], list[float], list[float]]:
    """Position (m, libnifalcon frame) → (θ1, θ2, θ3), each one value per leg, rad."""
    x, y, z = (float(v) for v in p_m)
    theta1, theta2, theta3 = [], [], []
    for cos_phi, sin_phi in _LEGS:
        cu = cos_phi * x + sin_phi * y - M.BASE_U_M + M.EFFECTOR_U_M  # C = (u + c, v + f, w)
        cv = -sin_phi * x + cos_phi * y - M.BASE_V_M + M.EFFECTOR_V_M
        if abs(cv) > _B:
            raise KinematicsError("position out of the Falcon's reach (shin)")
        t3 = math.acos(cv / _B)
        reach = _BARS + _B * math.sin(t3)  # D
        rho = math.hypot(cu, z)
        k = (rho * rho + _A * _A - reach * reach) / (2.0 * _A)
        if abs(k) > rho:
            raise KinematicsError("position out of the Falcon's reach (thigh)")
        t1 = math.atan2(z, cu) - math.acos(k / rho)
        theta1.append(t1)
        theta2.append(math.atan2(z - _A * math.sin(t1), cu - _A * math.cos(t1)))
        theta3.append(t3)
    return theta1, theta2, theta3


def joint_rates(theta1, theta2, theta3) -> list[list[float]]:
    """∂θ1_i/∂p (rad/m), one row per leg: Stamper's Jacobian."""
    rows = []
    for (cos_phi, sin_phi), t1, t2, t3 in zip(_LEGS, theta1, theta2, theta3):
        s3 = math.sin(t3)
        den = _A * s3 * math.sin(t2 - t1)
        if abs(den) < 1e-9:
            raise KinematicsError("the Falcon is at a singular pose")
        n_u, n_v, n_w = s3 * math.cos(t2), math.cos(t3), s3 * math.sin(t2)
        rows.append(
            [
                (cos_phi * n_u - sin_phi * n_v) / den,
                (sin_phi * n_u + cos_phi * n_v) / den,
                n_w / den,
            ]
        )
    return rows


def _inverse3(m) -> list[list[float]]:
    (a, b, c), (d, e, f), (g, h, i) = m
    co = [
        [e * i - f * h, c * h - b * i, b * f - c * e],
        [f * g - d * i, a * i - c * g, c * d - a * f],
        [d * h - e * g, b * g - a * h, a * e - b * d],
    ]
    det = a * co[0][0] + b * co[1][0] + c * co[2][0]
    if det == 0.0:
        raise KinematicsError("the Falcon is at a singular pose")
    return [[v / det for v in row] for row in co]


def jacobian(p_m) -> np.ndarray:
    """J = ∂p/∂θ1 (m/rad) at a position."""
    return np.array(_inverse3(joint_rates(*inverse(p_m))))


def forward(theta1, guess_m=None, tolerance_rad: float = 1e-12) -> np.ndarray:
    """Thigh angles → position (m): Newton on `inverse`, halving steps that do not help."""
    target = [float(t) for t in theta1]
    p = [float(v) for v in (M.WORKSPACE_CENTRE_M if guess_m is None else guess_m)]
    angles = inverse(p)
    error = [t - a for t, a in zip(target, angles[0])]
    for _ in range(50):
        if max(map(abs, error)) < tolerance_rad:
            return np.array(p)
        j = _inverse3(joint_rates(*angles))
        step = [sum(j[r][k] * error[k] for k in range(3)) for r in range(3)]
        size = math.hypot(*error)
        for _halving in range(30):
            candidate = [v + dv for v, dv in zip(p, step)]
            try:
                new_angles = inverse(candidate)
                new_error = [t - a for t, a in zip(target, new_angles[0])]
                if math.hypot(*new_error) < size:
                    break
            except KinematicsError:
                pass
            step = [dv / 2.0 for dv in step]
        else:
            break
        p, angles, error = candidate, new_angles, new_error
    if max(map(abs, error)) < 1e-9:
        return np.array(p)
    raise KinematicsError("the Falcon's encoders match no reachable position")


def motor_commands(jacobian_m, force_n) -> list[int]:
    """Force (N, same axes) → the three signed motor commands, with J = ∂p/∂θ1 at the pose."""
    torque = np.asarray(jacobian_m, dtype=float).T @ np.asarray(force_n, dtype=float)
    counts, _factor = scale_to_limit(M.MOTOR_COUNTS_PER_NM * torque, M.MOTOR_COMMAND_LIMIT)
    return [int(c) for c in counts]  # int() truncates toward zero, as libnifalcon's conversion
