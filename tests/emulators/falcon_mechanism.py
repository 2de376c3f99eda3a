"""The Falcon's mechanism as a physical object, for the emulator: grip pose → thigh angles,
motor commands → force on the grip. Written from libnifalcon's published numbers and
Stamper's description of the leg, with our own equations (nothing from sasprobe).

Facts (libnifalcon, commit f7c727a):
- FalconGeometry.h: a = 60 mm thigh, b = 102.5 mm shin, c = 14.43 mm and f = −25 mm from
  the effector centre to a leg's shin joint, d = e = 11.25 mm joint bars, the leg base
  at r = 40 mm, s = −23.09 mm; legs at 90°, −30°, −150°, each turned a further +15°.
- FalconKinematicStamper.cpp (IK): in leg coordinates (u, v, w), the world turned by −φ
  about z, the shin's v extent is b·cos θ3, its sweep in the thigh's plane is
  d + e + b·sin θ3, from the knee at a·(cos θ1, sin θ1) in the (u, w) plane.
- FalconKinematic.h getTheta: 320 slots × 4 counts per motor turn, 14.25 mm shaft on a
  110 mm drum, count 0 at θ1 = 35° once homed.
- FalconKinematicStamper.cpp getForces: command = −10000 × thigh torque (N·m).
- FalconSphereTest.cpp: the workspace centre the examples use is z = 0.11 m.

Our equations: the knee is where the circle of radius a about the thigh's axis meets the
circle of radius d + e + √(b² − h²) about the shin joint (h: the joint's offset along the
axis) — a two-circle intersection; the mechanism is assembled knee-out (the knee on the
side away from the device's axis). The grip force of motor torques τ follows from virtual
work, F = Gᵀ τ, with G = ∂θ/∂p by central differences of that intersection.
"""

from __future__ import annotations

import math

import numpy as np

A, B, C, D, E, F = 0.060, 0.1025, 0.01443, 0.01125, 0.01125, -0.025
R, S = 0.0400, -0.02309
LEG_AZIMUTHS = [math.radians(deg + 15.0) for deg in (90.0, -30.0, -150.0)]
RAD_PER_COUNT = (0.01425 * math.pi / (320 * 4)) / (0.110 * math.pi) * 2.0 * math.pi
INDEX_ANGLE = math.radians(35.0)  # the thigh angle at count 0 once homed: the index mark
NM_PER_COMMAND = -1.0 / 10000.0
CENTRE_M = np.array([0.0, 0.0, 0.110])


class Unreachable(ValueError):
    pass


def mechanism_m(device_mm) -> np.ndarray:
    """The project's device frame (mm from the workspace centre) → libnifalcon's (m)."""
    return np.asarray(device_mm, dtype=float) / 1000.0 + CENTRE_M


def thigh_angles(p_m) -> np.ndarray:
    """The three thigh angles θ1 (rad) with the grip at p (m). Scalar math: it runs for
    every command the emulated firmware answers."""
    x, y, z = (float(v) for v in p_m)
    angles = []
    for phi in LEG_AZIMUTHS:
        cos_phi, sin_phi = math.cos(phi), math.sin(phi)
        # the shin joint relative to the leg base, in (radial, along the thigh's axis, z)
        radial = cos_phi * x + sin_phi * y + C - R
        h = -sin_phi * x + cos_phi * y + F - S
        if abs(h) >= B:
            raise Unreachable("the shin cannot reach")
        sweep = D + E + math.sqrt(B * B - h * h)
        dist = math.hypot(radial, z)  # the joint in the thigh's plane: (radial, z)
        if not abs(A - sweep) < dist < A + sweep:
            raise Unreachable("the thigh cannot reach")
        along = (A * A - sweep * sweep + dist * dist) / (2.0 * dist)
        across = math.sqrt(A * A - along * along)
        ux, uz = radial / dist, z / dist
        knees = [
            (along * ux - side * across * uz, along * uz + side * across * ux)
            for side in (1.0, -1.0)
        ]
        knee = max(knees, key=lambda k: k[0])  # knee-out: the one farther from the device's axis
        angles.append(math.atan2(knee[1], knee[0]))
    return np.array(angles)


def angle_rates(p_m, step_m: float = 1e-7) -> np.ndarray:
    """G[i, j] = ∂θ_i/∂p_j (rad/m) by central differences."""
    p = np.asarray(p_m, dtype=float)
    columns = []
    for j in range(3):
        dp = np.zeros(3)
        dp[j] = step_m
        columns.append((thigh_angles(p + dp) - thigh_angles(p - dp)) / (2.0 * step_m))
    return np.stack(columns, axis=1)


def grip_force(p_m, motor_commands) -> np.ndarray:
    """The force (N, libnifalcon's axes = the device frame's) the motors put on the grip."""
    torques = NM_PER_COMMAND * np.asarray(motor_commands, dtype=float)
    return angle_rates(p_m).T @ torques
