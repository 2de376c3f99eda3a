"""Arm kinematics against finite differences, round trips, virtual work and closed forms."""

from __future__ import annotations

import itertools
import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from sasprobe.devices.kinematics import DeltaArm, joint_torques, scale_to_limit, tip_force

RNG = np.random.default_rng(20240501)


def numeric_jacobian(f, q, h=1e-6):
    q = np.asarray(q, dtype=float)
    cols = []
    for i in range(len(q)):
        dq = np.zeros_like(q)
        dq[i] = h
        cols.append((f(q + dq) - f(q - dq)) / (2 * h))
    return np.stack(cols, axis=1)


# --- Falcon delta -------------------------------------------------------------------------

def closed_form_delta_fk(arm: DeltaArm, theta) -> np.ndarray:
    """Independent reference: trilaterate the three spheres of radius b around the knees.

    The grip p satisfies |p − c_i| = b with c_i = knee_i − s·u_i + grip offset.
    """
    theta = np.asarray(theta, dtype=float)
    centres = arm._knee(theta) - arm.g.platform_radius * arm._u + arm._grip
    p1, p2, p3 = centres
    ex = (p2 - p1) / np.linalg.norm(p2 - p1)
    i = ex @ (p3 - p1)
    ey = p3 - p1 - i * ex
    ey /= np.linalg.norm(ey)
    ez = np.cross(ex, ey)
    d = np.linalg.norm(p2 - p1)
    j = ey @ (p3 - p1)
    b = arm.g.shin
    x = d / 2.0
    y = (i * i + j * j) / (2 * j) - i * x / j
    z2 = b * b - x * x - y * y
    candidates = [p1 + x * ex + y * ey + s * math.sqrt(z2) * ez for s in (1.0, -1.0)]
    best = max(candidates, key=lambda c: c[2])  # the grip hangs toward the user (+Z)
    return best - arm.centre_mm


def delta_samples(n: int, half: float = 40.0):
    return [RNG.uniform(-half, half, size=3) for _ in range(n)]


def test_delta_numeric_forward_matches_the_closed_form_trilateration():
    arm = DeltaArm()
    for p in delta_samples(200):
        theta = arm.inverse(p)
        np.testing.assert_allclose(arm.forward(theta), closed_form_delta_fk(arm, theta), atol=1e-8)


def test_delta_inverse_undoes_forward_across_the_workspace_box():
    arm = DeltaArm()
    for corner in itertools.product((-40.0, 0.0, 40.0), repeat=3):
        theta = arm.inverse(corner)
        np.testing.assert_allclose(arm.forward(theta), corner, atol=1e-8)
        np.testing.assert_allclose(arm.inverse(arm.forward(theta)), theta, atol=1e-10)


def test_delta_newton_converges_from_a_poor_guess():
    arm = DeltaArm()
    target = np.array([35.0, -30.0, 38.0])
    theta = arm.inverse(target)
    np.testing.assert_allclose(arm.forward(theta, guess=[-38.0, 35.0, -38.0]), target, atol=1e-8)


def test_delta_jacobian_matches_finite_differences():
    arm = DeltaArm()
    for p in delta_samples(40):
        theta = arm.inverse(p)
        np.testing.assert_allclose(arm.jacobian(theta), numeric_jacobian(arm.forward, theta, h=1e-6), rtol=1e-5,
                                   atol=1e-4)


def test_delta_torques_do_the_same_virtual_work_as_the_force():
    arm = DeltaArm()
    for p in delta_samples(40):
        theta = arm.inverse(p)
        force = RNG.normal(size=3)
        torques, factor = arm.torques(theta, force, limit_nm=1e9)
        assert factor == 1.0
        dtheta = RNG.normal(size=3) * 1e-7
        work_tip = force @ (arm.forward(theta + dtheta) - arm.forward(theta)) / 1000.0
        assert torques @ dtheta == pytest.approx(work_tip, rel=1e-4, abs=1e-15)


def test_delta_torque_limit_scales_every_joint_by_one_factor():
    arm = DeltaArm()
    theta = arm.inverse([10.0, -20.0, 15.0])
    force = np.array([30.0, -12.0, 20.0])  # far beyond what the motors give
    torques, factor = arm.torques(theta, force, limit_nm=0.2)
    assert 0.0 < factor < 1.0
    assert np.max(np.abs(torques)) == pytest.approx(0.2)
    rendered = tip_force(arm.jacobian(theta), torques)
    np.testing.assert_allclose(rendered / np.linalg.norm(rendered), force / np.linalg.norm(force), atol=1e-9)
    np.testing.assert_allclose(rendered, factor * force, rtol=1e-9)


@settings(max_examples=200, deadline=None)
@given(st.lists(st.floats(-1e6, 1e6), min_size=3, max_size=3), st.floats(1e-3, 10.0))
def test_scale_to_limit_never_exceeds_and_keeps_direction(torques, limit):
    scaled, factor = scale_to_limit(np.array(torques), limit)
    assert np.all(np.abs(scaled) <= limit * (1 + 1e-12))
    np.testing.assert_allclose(scaled, factor * np.array(torques), rtol=1e-12, atol=1e-300)


def test_tip_force_inverts_joint_torques():
    arm = DeltaArm()
    theta = arm.inverse([5.0, 5.0, -5.0])
    jac = arm.jacobian(theta)
    force = np.array([1.0, -2.0, 0.5])
    np.testing.assert_allclose(tip_force(jac, joint_torques(jac, force)), force, atol=1e-12)
