"""DHD's frame → sasprobe's device frame, the one place it is written.

DHD (chai3d/chai3d @ 7c76b1f2, src/devices/CMyCustomDevice.cpp l. 424–427, the frame
CHAI3D's Force Dimension driver passes through unchanged): x toward the user, y to the
user's right, z up, metres, origin at the workspace centre (once CHAI3D's per-model
offset is added). sasprobe: x right, y up, z toward the user, millimetres. So
X = 1000·y, Y = 1000·z, Z = 1000·x: a cyclic permutation of the axes, a rotation, so
forces map back with its transpose and orientations as P·R·Pᵀ.
"""

from __future__ import annotations

import numpy as np

DHD_TO_DEVICE = np.array([[0.0, 1.0, 0.0], [0.0, 0.0, 1.0], [1.0, 0.0, 0.0]])


def position_mm(dhd_m) -> np.ndarray:
    return DHD_TO_DEVICE @ np.asarray(dhd_m, dtype=float) * 1000.0


def velocity_mm_s(dhd_m_s) -> np.ndarray:
    return DHD_TO_DEVICE @ np.asarray(dhd_m_s, dtype=float) * 1000.0


def dhd_force(device_force_n) -> np.ndarray:
    return DHD_TO_DEVICE.T @ np.asarray(device_force_n, dtype=float)


def rotation(dhd_matrix) -> np.ndarray:
    return DHD_TO_DEVICE @ np.asarray(dhd_matrix, dtype=float) @ DHD_TO_DEVICE.T
