"""What every arm's kinematics shares: the error for an unreachable pose, the one common
scale factor that keeps a force's direction when a torque exceeds its limit (§3), and
rotations as unit quaternions (w, x, y, z), the orientation every driver reports.

Each arm keeps its mechanism in its own package (`falcon/kinematics.py`,
`woodenhaptics/kinematics.py`, `haply/kinematics.py`).
"""

from __future__ import annotations

import math

import numpy as np


class KinematicsError(ValueError):
    """A pose outside the mechanism's reach, or a singular configuration."""


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


def quaternion_about(axis, angle_rad: float) -> np.ndarray:
    """Unit quaternion (w, x, y, z) of a rotation by `angle_rad` about `axis`."""
    axis = np.asarray(axis, dtype=float)
    axis = axis / np.linalg.norm(axis)
    half = angle_rad / 2.0
    return np.concatenate([[math.cos(half)], math.sin(half) * axis])


def quaternion_multiply(a, b) -> np.ndarray:
    """Hamilton product a·b (apply b first, then a)."""
    aw, ax, ay, az = a
    bw, bx, by, bz = b
    return np.array(
        [
            aw * bw - ax * bx - ay * by - az * bz,
            aw * bx + ax * bw + ay * bz - az * by,
            aw * by - ax * bz + ay * bw + az * bx,
            aw * bz + ax * by - ay * bx + az * bw,
        ]
    )


def quaternion_from_matrix(m) -> np.ndarray:
    """Unit quaternion (w, x, y, z) of a 3x3 rotation matrix (Shepperd's method)."""
    m = np.asarray(m, dtype=float)
    trace = m[0, 0] + m[1, 1] + m[2, 2]
    if trace > 0:
        s = 2.0 * math.sqrt(trace + 1.0)
        q = [0.25 * s, (m[2, 1] - m[1, 2]) / s, (m[0, 2] - m[2, 0]) / s, (m[1, 0] - m[0, 1]) / s]
    elif m[0, 0] > m[1, 1] and m[0, 0] > m[2, 2]:
        s = 2.0 * math.sqrt(1.0 + m[0, 0] - m[1, 1] - m[2, 2])
        q = [(m[2, 1] - m[1, 2]) / s, 0.25 * s, (m[0, 1] + m[1, 0]) / s, (m[0, 2] + m[2, 0]) / s]
    elif m[1, 1] > m[2, 2]:
        s = 2.0 * math.sqrt(1.0 + m[1, 1] - m[0, 0] - m[2, 2])
        q = [(m[0, 2] - m[2, 0]) / s, (m[0, 1] + m[1, 0]) / s, 0.25 * s, (m[1, 2] + m[2, 1]) / s]
    else:
        s = 2.0 * math.sqrt(1.0 + m[2, 2] - m[0, 0] - m[1, 1])
        q = [(m[1, 0] - m[0, 1]) / s, (m[0, 2] + m[2, 0]) / s, (m[1, 2] + m[2, 1]) / s, 0.25 * s]
    q = np.asarray(q)
    q = q / np.linalg.norm(q)
    return q if q[0] >= 0 else -q
