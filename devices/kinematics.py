"""Arm kinematics: joint angles ↔ tip position, Jacobians, force → joint torques.

Three mechanisms, all in millimetres and radians (torques come out in N·m):

- the PHANTOM family (PHANTOM Omni/Touch/Premium, WoodenHaptics' Woody and the
  retrofitted vintage PHANTOM): a waist, a shoulder and an elbow whose angle is measured
  from vertical because the forearm is driven through a parallelogram/cable
  (haptics research notes §4). One parameter table, `PHANTOM_MODELS`.
- the Novint Falcon's rotary delta: forward kinematics is solved numerically (Newton on
  the inverse kinematics, step halving when the residual grows), the force mapping is
  τ = Jᵀ·F with one common scale factor when any torque exceeds the limit (§3).
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
