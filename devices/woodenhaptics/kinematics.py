"""Counts → body angles → tip, and tip force → motor currents, as hfabapi computes them.

forsslund/hfabapi at cf00e97, `hfab_kinematics.cpp`:
- `calculate_pose()`: motor angle = 2π·counts / cpr; body angle = dir · motor angle ·
  capstan ∅ / body ∅, dir = −1 where motor and body are aligned (a cable capstan turns
  its drum the other way), +1 otherwise; the counts include the model's home counts;
- `computePosition()`, every model but Polhem: x = cos tA·(Lb sin tB + Lc sin tC),
  y = sin tA·(Lb sin tB + Lc sin tC), z = Ln + Lb cos tB − Lc cos tC, minus the
  workspace origin;
- Polhem (`hfab_polhem.h` `polhemKinematics()`): a four-bar in the plane of body B —
  body B (L1, angle tB) pivots at +L0/2, a crank (L2, angle tC) at −L0/2, a coupler
  (L3) joins the crank to the far end (L4) of the output link, whose other end (L5)
  carries the tip; λ, the output link's angle, closes the loop;
- `computeMotorAmps()`: joint torques τ = Jᵀ·F (the closed form for the serial
  models, central differences of the position for Polhem), motor torque = τ · dir ·
  capstan ∅ / body ∅, current = motor torque / torque constant;
- `hfab_api.cpp` `getRot()`: the stylus orientation rot_z(tA)·rot_y(−λ)·rot_D(tD)·
  rot_y(tE)·rot_x(tF) from the gimbal counts (λ only for Polhem; D about z on the
  vintage PHANTOM, about x otherwise).

Device frame: hfabapi's position is metres with x toward the user, y right, z up
(`hfab_api.h` `derived_values`), origin at the workspace origin. Ours is millimetres,
X right, Y up, Z toward the user, same origin: X = 1000·y, Y = 1000·z, Z = 1000·x (a
rotation: the axes permute cyclically). Forces map the same way.

What we leave out: hfabapi's gravity compensation. It is zero for the serial models
(`g_constant` 0) but always on for Polhem (`polhemComputeMotorAmps()`, link masses of
`hfab_polhem.h`); sasprobe sends the Jᵀ·F part only, so a Polhem arm's own weight is felt.
"""

from __future__ import annotations

import functools
import math

import numpy as np
from sasprobe.devices.kinematics import KinematicsError, quaternion_from_matrix, scale_to_limit
from sasprobe.devices.woodenhaptics.models import POLHEM, POLHEM_LINKS_M, WoodenModel
from sasprobe.devices.woodenhaptics.protocol import MAX_CURRENT_MA

# rows: device X, Y, Z in terms of hfab x (toward the user), y (right), z (up)
HFAB_TO_DEVICE = np.array([[0.0, 1.0, 0.0], [0.0, 0.0, 1.0], [1.0, 0.0, 0.0]])
POLHEM_JACOBIAN_STEP = 1e-6  # rad, central differences as polhemComputeMotorAmps() takes them


@functools.cache
def _drive(model: WoodenModel) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Per motor: body radians per count, body→motor torque factor (dir · capstan∅ / body∅),
    amperes per N·m of motor torque, home counts. Computed once per model."""
    direction = np.where(model.motor_and_body_aligned, -1.0, 1.0)
    ratio = np.asarray(model.capstan_diameters_m) / np.asarray(model.body_diameters_m)
    per_count = direction * ratio * 2.0 * math.pi / np.asarray(model.counts_per_turn, dtype=float)
    return (
        per_count,
        direction * ratio,
        1.0 / np.asarray(model.torque_constants_nm_per_a),
        np.asarray(model.home_counts[:3], dtype=float),
    )


def body_angles(model: WoodenModel, raw_counts) -> np.ndarray:
    """tA, tB, tC (rad) of the three motor counts the firmware sent (home counts added here)."""
    per_count, _torque, _amps, home = _drive(model)
    return (np.asarray(raw_counts[:3], dtype=float) + home) * per_count


def polhem_tip(angles) -> tuple[np.ndarray, float]:
    """Polhem's tip (hfab frame, m, before the origin is subtracted) and λ; NaN where the loop
    cannot close."""
    t1, t2, t3 = angles
    l0, l1, l2, l3, l4, l5 = POLHEM_LINKS_M
    to_b_from_crank_pivot = np.array([l0 + l1 * math.cos(t2), l1 * math.sin(t2)])  # B − O2
    # B − A
    to_b_from_crank_end = to_b_from_crank_pivot - l2 * np.array([math.cos(t3), math.sin(t3)])
    rho2 = float(np.hypot(*to_b_from_crank_pivot))
    rho1 = float(np.hypot(*to_b_from_crank_end))
    with np.errstate(invalid="ignore"):
        at_b_o1_o2 = np.arccos((l1 * l1 + rho2 * rho2 - l0 * l0) / (2.0 * l1 * rho2))
        at_b_o2_a = np.arccos((rho2 * rho2 + rho1 * rho1 - l2 * l2) / (2.0 * rho2 * rho1))
        at_b_a_c = np.arccos((l4 * l4 + rho1 * rho1 - l3 * l3) / (2.0 * l4 * rho1))
    lam = float(t2 - at_b_o1_o2 - at_b_o2_a - at_b_a_c)
    reach = l0 / 2.0 + l1 * math.cos(t2) + l5 * math.cos(lam)
    return np.array(
        [reach * math.cos(t1), reach * math.sin(t1), l1 * math.sin(t2) + l5 * math.sin(lam)]
    ), lam


def hfab_position(model: WoodenModel, angles) -> tuple[np.ndarray, float]:
    """(tip in hfab's frame, m, relative to the workspace origin; λ, 0 for the serial models)."""
    if model.mechanism == POLHEM:
        tip, lam = polhem_tip(angles)
    else:
        ta, tb, tc = angles
        ln, lb, lc = model.body_lengths_m
        reach = lb * math.sin(tb) + lc * math.sin(tc)
        tip = np.array(
            [math.cos(ta) * reach, math.sin(ta) * reach, ln + lb * math.cos(tb) - lc * math.cos(tc)]
        )
        lam = 0.0
    return tip - np.asarray(model.workspace_origin_m), lam


def hfab_jacobian(model: WoodenModel, angles) -> np.ndarray:
    """∂(hfab tip)/∂(tA, tB, tC), m/rad."""
    if model.mechanism == POLHEM:
        columns = []
        for i in range(3):
            step = np.zeros(3)
            step[i] = POLHEM_JACOBIAN_STEP / 2.0
            columns.append(
                (
                    polhem_tip(np.asarray(angles) + step)[0]
                    - polhem_tip(np.asarray(angles) - step)[0]
                )
                / POLHEM_JACOBIAN_STEP
            )
        return np.stack(columns, axis=1)
    ta, tb, tc = angles
    _ln, lb, lc = model.body_lengths_m
    reach = lb * math.sin(tb) + lc * math.sin(tc)
    return np.array(
        [
            [
                -math.sin(ta) * reach,
                lb * math.cos(ta) * math.cos(tb),
                lc * math.cos(ta) * math.cos(tc),
            ],
            [
                math.cos(ta) * reach,
                lb * math.sin(ta) * math.cos(tb),
                lc * math.sin(ta) * math.cos(tc),
            ],
            [0.0, -lb * math.sin(tb), lc * math.sin(tc)],
        ]
    )


def tip_position_mm(model: WoodenModel, angles) -> tuple[np.ndarray, float]:
    """(tip in the device frame, mm; λ). KinematicsError where the linkage cannot close."""
    tip, lam = hfab_position(model, angles)
    if not np.all(np.isfinite(tip)):
        raise KinematicsError(
            f"the {model.name} linkage cannot reach encoder angles "
            f"{np.degrees(angles).round(1).tolist()}° (was it calibrated in its home pose?)"
        )
    return HFAB_TO_DEVICE @ tip * 1000.0, lam


def motor_currents_ma(model: WoodenModel, angles, force_n) -> np.ndarray:
    """Currents (mA) rendering a device-frame force at these body angles, all scaled by one
    factor to stay within the firmware's ±6000 mA (beyond it the firmware sends 0)."""
    _per_count, torque, amps, _home = _drive(model)
    force_hfab = HFAB_TO_DEVICE.T @ np.asarray(force_n, dtype=float)
    joint = hfab_jacobian(model, angles).T @ force_hfab  # N·m on the bodies
    currents = joint * torque * amps * 1000.0
    if not np.all(np.isfinite(currents)):
        return np.zeros(3)
    return scale_to_limit(currents, MAX_CURRENT_MA)[0]


def orientation(model: WoodenModel, angles, lam: float, raw_counts) -> np.ndarray:
    """Stylus orientation (w, x, y, z) in the device frame from the gimbal counts (getRot())."""
    cpr_d, cpr_e, cpr_f = model.gimbal_counts_per_turn
    if not (cpr_d and cpr_e and cpr_f):
        return np.array([1.0, 0.0, 0.0, 0.0])  # no gimbal encoders: hfabapi reports identity too
    counts = np.asarray(raw_counts[3:6], dtype=float) + np.asarray(model.home_counts[3:6])
    sign_d, sign_e = np.where(model.gimbal_aligned, 1.0, -1.0)
    t_d = sign_d * counts[0] * 2.0 * math.pi / cpr_d
    t_e = sign_e * counts[1] * 2.0 * math.pi / cpr_e
    t_f = counts[2] * 2.0 * math.pi / cpr_f
    rot_d = _rot_z(t_d) if model.gimbal_d_axis == "z" else _rot_x(t_d)
    hfab = _rot_z(angles[0]) @ _rot_y(-lam) @ rot_d @ _rot_y(t_e) @ _rot_x(t_f)
    return quaternion_from_matrix(HFAB_TO_DEVICE @ hfab @ HFAB_TO_DEVICE.T)


def _rot_x(t: float) -> np.ndarray:
    c, s = math.cos(t), math.sin(t)
    return np.array([[1.0, 0.0, 0.0], [0.0, c, -s], [0.0, s, c]])


def _rot_y(t: float) -> np.ndarray:
    c, s = math.cos(t), math.sin(t)
    return np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])


def _rot_z(t: float) -> np.ndarray:
    c, s = math.cos(t), math.sin(t)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
