"""The 2DIY pantograph as Haply's library solves it, and its frame in ours.

HaplyHAPI 1.0.1 `Pantograph.forwardKinematics()`: link 1's motor at the origin, link
2's at (d, 0); the elbows A = l·(cos θ1, sin θ1) and B = (d, 0) + l·(cos θ2, sin θ2);
the handle P = A + L·(cos β·ĥ + sin β·ĥ⊥), with ĥ the unit vector from A to B, ĥ⊥ it
turned +90° and cos β = |AB| / 2L: of the two points at distance L from both elbows,
the one on the left of A→B. Torques are τ = Jᵀ·F (`torqueCalculation()`, gain 1).

Frame: the pantograph's x points to the user's left and y toward the user, angles
counter-clockwise seen from above — as Haply's Processing examples draw it
(Haply-API-Java at 8e95d33 `Hello_Wall.pde`: the tool's screen x is the world centre
minus x, its screen y grows with y, and the force sent back is (−fx, fy)). Ours:
X = −(x − cx), Y = 0 (the pad is flat on the desk), Z = y − cy, in mm, around the
generation's workspace centre (cx, cy). A force's Y part cannot be rendered and is dropped.
"""

from __future__ import annotations

import math

import numpy as np
from sasprobe.devices.haply.models import Generation
from sasprobe.devices.kinematics import KinematicsError


def elbows(gen: Generation, theta) -> tuple[np.ndarray, np.ndarray]:
    t1, t2 = theta
    a = gen.proximal_m * np.array([math.cos(t1), math.sin(t1)])
    b = np.array([gen.motor_spacing_m, 0.0]) + gen.proximal_m * np.array(
        [math.cos(t2), math.sin(t2)]
    )
    return a, b


def handle(gen: Generation, theta) -> np.ndarray:
    """Handle (x, y) in the pantograph frame, m."""
    a, b = elbows(gen, theta)
    chord = b - a
    span = float(np.hypot(*chord))
    if span == 0.0 or span >= 2.0 * gen.distal_m:
        raise KinematicsError(
            f"the 2DIY links cannot meet at motor angles {np.degrees(theta).round(1).tolist()}°"
        )
    along = chord / span
    cos_b = span / (2.0 * gen.distal_m)
    return a + gen.distal_m * (
        cos_b * along + math.sqrt(1.0 - cos_b * cos_b) * np.array([-along[1], along[0]])
    )


def jacobian(gen: Generation, theta) -> np.ndarray:
    """∂(x, y)/∂(θ1, θ2), m/rad: from (P − A)·(dP − dA) = 0 and (P − B)·(dP − dB) = 0."""
    p = handle(gen, theta)
    a, b = elbows(gen, theta)
    t1, t2 = theta
    da = gen.proximal_m * np.array([-math.sin(t1), math.cos(t1)])
    db = gen.proximal_m * np.array([-math.sin(t2), math.cos(t2)])
    rows = np.stack([p - a, p - b])
    return np.linalg.solve(rows, np.diag([(p - a) @ da, (p - b) @ db]))


def to_device_mm(gen: Generation, xy) -> np.ndarray:
    cx, cy = gen.workspace_centre_m
    return np.array([-(xy[0] - cx), 0.0, xy[1] - cy]) * 1000.0


def force_in_plane(force_n) -> np.ndarray:
    """A device-frame force as the pantograph's (fx, fy); its Y part is dropped."""
    return np.array([-force_n[0], force_n[2]], dtype=float)


def link_torques(gen: Generation, theta, force_n) -> np.ndarray:
    """(τ1, τ2) N·m on links 1 and 2 that render a device-frame force."""
    return jacobian(gen, theta).T @ force_in_plane(force_n)
