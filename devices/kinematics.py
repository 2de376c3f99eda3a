"""What every arm's kinematics shares: the error for an unreachable pose and the one
common scale factor that keeps a force's direction when a torque exceeds its limit (§3).

Each arm keeps its mechanism in its own package (`falcon/kinematics.py`,
`woodenhaptics/kinematics.py`, `haply/kinematics.py`).
"""

from __future__ import annotations

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
