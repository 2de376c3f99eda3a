"""Arm kinematics against finite differences, round trips, virtual work and closed forms."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from sasprobe.devices.kinematics import (ARM_TO_DEVICE, PHANTOM_MODELS, KinematicsError, PantographArm,
                                         PhantomArm, joint_torques, scale_to_limit, tip_force)

RNG = np.random.default_rng(20240501)


def numeric_jacobian(f, q, h=1e-6):
    q = np.asarray(q, dtype=float)
    cols = []
    for i in range(len(q)):
        dq = np.zeros_like(q)
        dq[i] = h
        cols.append((f(q + dq) - f(q - dq)) / (2 * h))
    return np.stack(cols, axis=1)


def phantom_samples(arm: PhantomArm, n: int):
    g = arm.geometry
    out = []
    while len(out) < n:
        q = RNG.uniform(g.joint_min, g.joint_max)
        if arm.on_elbow_branch(q) and abs(abs(q[2] - q[1]) - math.pi / 2) > 0.05:
            out.append(q)
    return out


# --- PHANTOM family ---------------------------------------------------------------------

@pytest.mark.parametrize("model", sorted(PHANTOM_MODELS))
def test_phantom_inverse_undoes_forward(model):
    arm = PhantomArm(PHANTOM_MODELS[model])
    for q in phantom_samples(arm, 300):
        p = arm.forward(q)
        np.testing.assert_allclose(arm.inverse(p), q, atol=1e-9)
        np.testing.assert_allclose(arm.forward(arm.inverse(p)), p, atol=1e-9)


def test_phantom_forward_matches_the_published_formula_at_hand_picked_poses():
    # Worked by hand from x = r cos q1, y = r sin q1, z = L1 sin q2 − L2 cos q3, r = L1 cos q2 + L2 sin q3
    arm = PhantomArm(PHANTOM_MODELS["omni"])
    l1 = l2 = 133.35
    for q, tip_arm in [((0.0, 0.0, 0.0), (l1, 0.0, -l2)),
                       ((math.pi / 2, 0.0, math.pi / 2), (0.0, l1 + l2, 0.0)),
                       ((0.0, math.pi / 2, 0.0), (0.0, 0.0, l1 - l2))]:
        expected = ARM_TO_DEVICE @ (np.array(tip_arm) - arm._fk_arm(np.array(arm.geometry.centre_joint_angles)))
        np.testing.assert_allclose(arm.forward(q), expected, atol=1e-9)


def test_phantom_device_frame_is_x_right_y_up_z_toward_the_user():
    arm = PhantomArm(PHANTOM_MODELS["omni"])
    q = np.array(arm.geometry.centre_joint_angles)
    np.testing.assert_allclose(arm.forward(q), 0.0, atol=1e-12)  # origin at the workspace centre
    assert arm.forward(q + [0, 0.1, 0])[1] > 0  # raising the upper arm lifts the tip (+Y)
    assert arm.forward(q + [0, 0, 0.1])[2] < 0  # swinging the forearm forward moves away from the user


@pytest.mark.parametrize("model", ["omni", "premium-1.5", "woody"])
def test_phantom_jacobian_matches_finite_differences(model):
    arm = PhantomArm(PHANTOM_MODELS[model])
    for q in phantom_samples(arm, 50):
        np.testing.assert_allclose(arm.jacobian(q), numeric_jacobian(arm.forward, q), atol=1e-5)


def test_phantom_torques_do_the_same_virtual_work_as_the_force():
    arm = PhantomArm(PHANTOM_MODELS["omni"])
    for q in phantom_samples(arm, 50):
        force = RNG.normal(size=3)
        dq = RNG.normal(size=3) * 1e-7
        work_tip = force @ (arm.forward(q + dq) - arm.forward(q)) / 1000.0  # N·mm → J
        work_joints = arm.torques(q, force) @ dq
        assert work_joints == pytest.approx(work_tip, rel=1e-4, abs=1e-15)


def test_phantom_out_of_reach_is_an_error():
    arm = PhantomArm(PHANTOM_MODELS["omni"])
    with pytest.raises(KinematicsError):
        arm.inverse([0.0, 0.0, -400.0])


@settings(max_examples=200, deadline=None)
@given(st.lists(st.floats(-1e6, 1e6), min_size=3, max_size=3), st.floats(1e-3, 10.0))
def test_scale_to_limit_never_exceeds_and_keeps_direction(torques, limit):
    scaled, factor = scale_to_limit(np.array(torques), limit)
    assert np.all(np.abs(scaled) <= limit * (1 + 1e-12))
    np.testing.assert_allclose(scaled, factor * np.array(torques), rtol=1e-12, atol=1e-300)


# --- Haply pantograph ----------------------------------------------------------------------

def pantograph_samples(n: int):
    arm = PantographArm()
    out = []
    while len(out) < n:
        p = np.array([RNG.uniform(-60, 60), RNG.uniform(-110, -40)])
        try:
            arm.inverse(p)
        except KinematicsError:
            continue
        out.append(p)
    return out


def test_pantograph_round_trip_and_link_lengths():
    arm = PantographArm()
    for p in pantograph_samples(200):
        theta = arm.inverse(p)
        np.testing.assert_allclose(arm.forward(theta), p, atol=1e-9)
        elbows = arm._elbows(theta)
        np.testing.assert_allclose(np.linalg.norm(p - elbows, axis=1), arm.g.L_mm, atol=1e-9)


def test_pantograph_start_pose_is_both_links_straight_out():
    arm = PantographArm()
    p = arm.forward(np.radians([180.0, 0.0]))
    assert p[0] == pytest.approx(0.0, abs=1e-12)
    assert p[1] == pytest.approx(-math.sqrt(arm.g.L_mm ** 2 - arm.g.l_mm ** 2))


def test_pantograph_jacobian_and_virtual_work():
    arm = PantographArm()
    for p in pantograph_samples(40):
        theta = arm.inverse(p)
        np.testing.assert_allclose(arm.jacobian(theta), numeric_jacobian(arm.forward, theta), atol=1e-4)
        force = RNG.normal(size=2)
        dtheta = RNG.normal(size=2) * 1e-7
        work_tip = force @ (arm.forward(theta + dtheta) - arm.forward(theta)) / 1000.0
        assert arm.torques(theta, force) @ dtheta == pytest.approx(work_tip, rel=1e-4, abs=1e-15)


def test_tip_force_inverts_joint_torques():
    arm = PhantomArm(PHANTOM_MODELS["omni"])
    jac = arm.jacobian(arm.inverse([5.0, 5.0, -5.0]))
    force = np.array([1.0, -2.0, 0.5])
    np.testing.assert_allclose(tip_force(jac, joint_torques(jac, force)), force, atol=1e-12)
