"""Arm kinematics: joint angles ↔ tip position, Jacobians, force → joint torques.

Two mechanisms, all in millimetres and radians (torques come out in N·m), and the
pieces every arm shares (the Falcon's Stamper kinematics live in `devices/falcon/`):

- the PHANTOM family (PHANTOM Omni/Touch/Premium, WoodenHaptics' Woody and the
  retrofitted vintage PHANTOM): a waist, a shoulder and an elbow whose angle is measured
  from vertical because the forearm is driven through a parallelogram/cable
  (haptics research notes §4). One parameter table, `PHANTOM_MODELS`.
- the Haply 2DIY's planar pantograph (a five-bar linkage).

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
# PHANTOM family
# --------------------------------------------------------------------------------------

@dataclass(frozen=True)
class PhantomGeometry:
    """Link lengths of a PHANTOM-family arm and where its workspace centre lies.

    Arm frame: z up, x forward (away from the user) at waist angle 0, y to the user's left.
    The device frame the drivers report is the OpenHaptics-style one: X right, Y up,
    Z toward the user, origin at the workspace centre (`centre_joint_angles`).
    """

    name: str
    l1_mm: float  # upper arm, shoulder → elbow
    l2_mm: float  # forearm, elbow → stylus tip (gimbal centre)
    centre_joint_angles: tuple[float, float, float]  # (q1, q2, q3) rad at the workspace centre
    joint_min: tuple[float, float, float]
    joint_max: tuple[float, float, float]


# Link lengths: Omni/Touch from the URDF and Jarillo-Silva et al. (L1 = L2 = 133.35 mm);
# Premium 1.5 from the public FK snippet (209.55 / 169.545 mm). Woody and the vintage
# PHANTOM (WoodenHaptics models 3 and 2) are nominal builds: measure yours and edit here.
# Joint limits: the Omni URDF's (waist ±0.98, shoulder 0..1.75, elbow −0.81..1.25 rad).
PHANTOM_MODELS: dict[str, PhantomGeometry] = {
    "omni": PhantomGeometry("PHANTOM Omni", 133.35, 133.35, (0.0, 0.35, 0.35),
                            (-0.98, 0.0, -0.81), (0.98, 1.75, 1.25)),
    "touch": PhantomGeometry("Touch", 133.35, 133.35, (0.0, 0.35, 0.35),
                             (-0.98, 0.0, -0.81), (0.98, 1.75, 1.25)),
    "premium-1.5": PhantomGeometry("PHANTOM Premium 1.5", 209.55, 169.545, (0.0, 0.35, 0.35),
                                   (-1.0, -0.2, -0.8), (1.0, 1.6, 1.3)),
    "vintage-phantom": PhantomGeometry("vintage PHANTOM (WoodenHaptics retrofit)", 139.7, 139.7,
                                       (0.0, 0.35, 0.35), (-1.0, -0.2, -0.8), (1.0, 1.6, 1.3)),
    "woody": PhantomGeometry("WoodenHaptics Woody", 200.0, 200.0, (0.0, 0.35, 0.35),
                             (-1.0, -0.2, -0.8), (1.0, 1.6, 1.3)),
}

# Arm frame (x forward, y left, z up) → device frame (X right, Y up, Z toward the user).
ARM_TO_DEVICE = np.array([[0.0, -1.0, 0.0], [0.0, 0.0, 1.0], [-1.0, 0.0, 0.0]])


class PhantomArm:
    """Forward/inverse kinematics and Jacobian of one PHANTOM-family geometry."""

    def __init__(self, geometry: PhantomGeometry):
        self.geometry = geometry
        self.l1 = geometry.l1_mm
        self.l2 = geometry.l2_mm
        self._centre = self._fk_arm(np.asarray(geometry.centre_joint_angles, dtype=float))

    # arm frame -----------------------------------------------------------------------
    def _fk_arm(self, q: np.ndarray) -> np.ndarray:
        q1, q2, q3 = q
        r = self.l1 * math.cos(q2) + self.l2 * math.sin(q3)
        return np.array([r * math.cos(q1), r * math.sin(q1), self.l1 * math.sin(q2) - self.l2 * math.cos(q3)])

    def _jacobian_arm(self, q: np.ndarray) -> np.ndarray:
        q1, q2, q3 = q
        r = self.l1 * math.cos(q2) + self.l2 * math.sin(q3)
        c1, s1 = math.cos(q1), math.sin(q1)
        return np.array([
            [-r * s1, -self.l1 * math.sin(q2) * c1, self.l2 * math.cos(q3) * c1],
            [r * c1, -self.l1 * math.sin(q2) * s1, self.l2 * math.cos(q3) * s1],
            [0.0, self.l1 * math.cos(q2), self.l2 * math.sin(q3)],
        ])

    # device frame --------------------------------------------------------------------
    def forward(self, q) -> np.ndarray:
        """Joint angles (rad) → tip position (mm) in the device frame."""
        return ARM_TO_DEVICE @ (self._fk_arm(np.asarray(q, dtype=float)) - self._centre)

    def jacobian(self, q) -> np.ndarray:
        """∂(device position)/∂q, mm/rad."""
        return ARM_TO_DEVICE @ self._jacobian_arm(np.asarray(q, dtype=float))

    @staticmethod
    def on_elbow_branch(q) -> bool:
        """True on the branch the mechanism can reach: upper arm and forearm less than 90°
        from perpendicular (|q3 − q2| < π/2); `inverse` returns this branch."""
        return abs(q[2] - q[1]) < math.pi / 2.0

    def inverse(self, p) -> np.ndarray:
        """Tip position (device frame, mm) → joint angles (rad) on the elbow branch."""
        x, y, z = ARM_TO_DEVICE.T @ np.asarray(p, dtype=float) + self._centre
        q1 = math.atan2(y, x)
        r = math.hypot(x, y)
        # (r − L1 cos q2)² + (z − L1 sin q2)² = L2²  ⇒  r cos q2 + z sin q2 = k
        k = (r * r + z * z + self.l1 ** 2 - self.l2 ** 2) / (2.0 * self.l1)
        rho = math.hypot(r, z)
        if rho == 0.0 or abs(k) > rho:
            raise KinematicsError(f"position {np.round(p, 1).tolist()} mm is out of the arm's reach")
        q2 = math.atan2(z, r) + math.acos(k / rho)
        q3 = math.atan2(r - self.l1 * math.cos(q2), -(z - self.l1 * math.sin(q2)))
        return np.array([q1, q2, q3])

    def torques(self, q, force_n) -> np.ndarray:
        """Joint torques (N·m) that render a device-frame tip force (N)."""
        return joint_torques(self.jacobian(q), force_n)


# --------------------------------------------------------------------------------------
# Haply 2DIY: planar pantograph (five-bar)
# --------------------------------------------------------------------------------------

@dataclass(frozen=True)
class PantographGeometry:
    """Five-bar: motors at (∓d/2, 0), proximal links `l`, distal links `L` meeting at the handle.

    Nominal 2DIY-class dimensions; measure yours. Angles are measured from +x,
    counter-clockwise; the handle works on the −y side (toward the user).
    """

    l_mm: float = 70.0
    L_mm: float = 90.0
    d_mm: float = 0.0


class PantographArm:
    def __init__(self, geometry: PantographGeometry | None = None):
        self.g = geometry or PantographGeometry()
        self._base = np.array([[-self.g.d_mm / 2.0, 0.0], [self.g.d_mm / 2.0, 0.0]])

    def _elbows(self, theta: np.ndarray) -> np.ndarray:
        return self._base + self.g.l_mm * np.stack([np.cos(theta), np.sin(theta)], axis=1)

    def forward(self, theta) -> np.ndarray:
        """Motor angles (rad) → handle (x, y) mm: the circle intersection below the elbows."""
        e1, e2 = self._elbows(np.asarray(theta, dtype=float))
        chord = e2 - e1
        dist = float(np.linalg.norm(chord))
        if dist == 0.0 or dist > 2.0 * self.g.L_mm:
            raise KinematicsError("pantograph links cannot meet")
        mid = (e1 + e2) / 2.0
        h = math.sqrt(self.g.L_mm ** 2 - (dist / 2.0) ** 2)
        normal = np.array([chord[1], -chord[0]]) / dist  # chord rotated −90°
        return mid + h * normal

    def inverse(self, p) -> np.ndarray:
        """Handle (x, y) mm → motor angles (rad), elbows outward."""
        p = np.asarray(p, dtype=float)
        theta = np.empty(2)
        for i, sign in ((0, 1.0), (1, -1.0)):
            v = p - self._base[i]
            rho = float(np.linalg.norm(v))
            cos_a = (self.g.l_mm ** 2 + rho ** 2 - self.g.L_mm ** 2) / (2.0 * self.g.l_mm * rho)
            if abs(cos_a) > 1.0:
                raise KinematicsError("handle out of the pantograph's reach")
            theta[i] = math.atan2(v[1], v[0]) - sign * math.acos(cos_a)
        return theta

    def jacobian(self, theta) -> np.ndarray:
        """∂(x, y)/∂θ, mm/rad, from |P − E_i|² = L² differentiated."""
        theta = np.asarray(theta, dtype=float)
        p = self.forward(theta)
        e = self._elbows(theta)
        w = p - e  # distal link vectors
        de = self.g.l_mm * np.stack([-np.sin(theta), np.cos(theta)], axis=1)
        a = w  # rows: w_iᵀ dp = (w_i · e_i') dθ_i
        b = np.diag(np.einsum("ij,ij->i", w, de))
        return np.linalg.solve(a, b)

    def torques(self, theta, force_xy) -> np.ndarray:
        return joint_torques(self.jacobian(theta), force_xy)
