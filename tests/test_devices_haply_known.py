"""Haply 2DIY: known answers computed here from Haply's own library (HaplyHAPI) and its board
protocol (the driver against the emulated board: test_devices_serial_arms.py and
test_devices_haply.py)."""

from __future__ import annotations

import math
import struct

import numpy as np
import pytest
from sasprobe.devices.haply import kinematics, protocol
from sasprobe.devices.haply.driver import create
from sasprobe.devices.haply.models import GENERATIONS

# HaplyHAPI 1.0.1 (PyPI) HaplyHAPI.py: Pantograph(version) l = 0.07, L = 0.09, d = 0.038
# (version 3) or 0 (2); the README example's add_actuator / add_encoder per version.
HAPLY = {
    "gen2": dict(l=0.07, L=0.09, d=0.0, centre=(0.0, 0.080)),
    "gen3": dict(l=0.07, L=0.09, d=0.038, centre=(0.019, 0.090)),
}  # centres: our assumption
ANGLES = {
    "gen2": [(241.0, -61.0), (200.0, -20.0), (225.0, -30.0), (190.0, -50.0)],
    "gen3": [(168.0, 12.0), (140.0, 40.0), (150.0, 20.0), (120.0, 35.0)],
}  # (θ1, θ2) degrees


def haply_forward(gen, deg1, deg2):
    """Pantograph.forwardKinematics() and its Jacobian terms, as HaplyHAPI.py writes them."""
    c = HAPLY[gen]
    l1 = l2 = c["l"]
    L1 = L2 = c["L"]
    d = c["d"]
    th1, th2 = math.pi / 180 * deg1, math.pi / 180 * deg2
    c1, c2, s1, s2 = math.cos(th1), math.cos(th2), math.sin(th1), math.sin(th2)
    xA, yA = l1 * c1, l1 * s1
    xB, yB = d + l2 * c2, l2 * s2
    hx, hy = xB - xA, yB - yA
    hh = hx**2 + hy**2
    hm = math.sqrt(hh)
    cB = -(L2**2 - L1**2 - hh) / (2 * L1 * hm)
    h1x, h1y = L1 * cB * hx / hm, L1 * cB * hy / hm
    h1m = math.sqrt(h1x**2 + h1y**2)
    sB = math.sqrt(1 - cB**2)
    lx, ly = -L1 * sB * h1y / h1m, L1 * sB * h1x / h1m
    x_P, y_P = xA + h1x + lx, yA + h1y + ly
    phi1 = math.acos((x_P - l1 * c1) / L1)
    phi2 = math.acos((x_P - d - l2 * c2) / L2)
    c11, s11, c22, s22 = math.cos(phi1), math.sin(phi1), math.cos(phi2), math.sin(phi2)
    dn = L1 * (c11 * s22 - c22 * s11)
    eta = (-L1 * c11 * s22 + L1 * c22 * s11 - c1 * l1 * s22 + c22 * l1 * s1) / dn
    nu = l2 * (c2 * s22 - c22 * s2) / dn
    J = (
        -L1 * eta * s11 - L1 * s11 - l1 * s1,
        L1 * c11 * eta + L1 * c11 + c1 * l1,
        -L1 * s11 * nu,
        L1 * c11 * nu,
    )
    return (x_P, y_P), J


@pytest.mark.parametrize("gen", ["gen2", "gen3"])
def test_handle_positions_match_haplys_solution(gen):
    for deg1, deg2 in ANGLES[gen]:
        (x, y), _ = haply_forward(gen, deg1, deg2)
        cx, cy = HAPLY[gen]["centre"]
        expected = [
            -(x - cx) * 1000,
            0.0,
            (y - cy) * 1000,
        ]  # X right = −pad x, Z toward the user = pad y
        got = kinematics.to_device_mm(
            GENERATIONS[gen], kinematics.handle(GENERATIONS[gen], np.radians([deg1, deg2]))
        )
        np.testing.assert_allclose(got, expected, atol=1e-9)


@pytest.mark.parametrize("gen", ["gen2", "gen3"])
def test_force_to_torque_matches_haplys_jacobian(gen):
    for deg1, deg2 in ANGLES[gen]:
        _, (J11, J12, J21, J22) = haply_forward(gen, deg1, deg2)
        for force in ([0.5, 0.0, 0.0], [0.0, 0.0, -0.8], [0.3, 9.0, 0.4]):  # Y cannot be rendered
            fx, fy = -force[0], force[2]
            expected = [J11 * fx + J12 * fy, J21 * fx + J22 * fy]  # torqueCalculation(), gain 1
            got = kinematics.link_torques(GENERATIONS[gen], np.radians([deg1, deg2]), force)
            np.testing.assert_allclose(got, expected, atol=1e-12)


def test_setup_write_and_reset_bytes_follow_haplys_library():
    # HaplyHAPI device_set_parameters(): motor mask, motor directions, encoder mask, encoder
    # directions, sensors, PWMs, then (offset, resolution) per encoder, all in port order.
    gen3 = protocol.encode_setup(5, GENERATIONS["gen3"].ports)
    assert gen3 == bytes([1, 5, 3, 1, 1, 3, 1, 1, 0, 0]) + struct.pack(
        "<4f", 12.0, 4880.0, 168.0, 4880.0
    )
    gen2 = protocol.encode_setup(5, GENERATIONS["gen2"].ports)
    assert gen2 == bytes([1, 5, 3, 0, 1, 3, 0, 1, 0, 0]) + struct.pack(
        "<4f", -61.0, 10752.0, 241.0, 10752.0
    )
    assert protocol.encode_write(5, [0.25, -0.5]) == bytes([2, 5]) + struct.pack("<2f", 0.25, -0.5)
    assert protocol.encode_reset() == bytes([0, 0])


def test_torques_go_to_the_ports_haply_assigns_and_are_clamped_together():
    dev = create("gen3:/dev/null")
    dev.theta = np.radians([150.0, 20.0])
    _, (J11, J12, J21, J22) = haply_forward("gen3", 150.0, 20.0)
    tau1, tau2 = J11 * -0.4, J21 * -0.4  # a force of 0.4 N along X: pad fx = −0.4
    np.testing.assert_allclose(
        dev.port_torques([0.4, 0.0, 0.0]), [tau2, tau1], atol=1e-12
    )  # port 1 drives link 2
    big = dev.port_torques([30.0, 0.0, -20.0])
    assert max(abs(t) for t in big) == pytest.approx(
        protocol.MAX_TORQUE_NM
    )  # the board clamps each at 0.123 N·m
    small = dev.port_torques([0.3, 0.0, -0.2])
    np.testing.assert_allclose(
        np.array(big) / np.linalg.norm(big), np.array(small) / np.linalg.norm(small), atol=1e-12
    )


def test_the_declared_force_is_renderable_everywhere_in_the_box():
    for gen in GENERATIONS.values():
        half = gen.limits.workspace_max_mm[0] / 1000.0
        cx, cy = gen.workspace_centre_m
        for x in np.linspace(cx - half, cx + half, 9):
            for y in np.linspace(cy - half, cy + half, 9):
                theta = _inverse(gen, x, y)
                jac = kinematics.jacobian(gen, theta)
                # the largest force the 0.123 N·m clamp allows in every direction
                assert (
                    protocol.MAX_TORQUE_NM
                    / max(np.linalg.norm(jac[:, 0]), np.linalg.norm(jac[:, 1]))
                    >= gen.limits.max_force_n
                )


def _inverse(gen, x, y):
    theta = np.radians([gen.port_for(1).start_angle_deg, gen.port_for(2).start_angle_deg])
    for _ in range(50):
        err = np.array([x, y]) - kinematics.handle(gen, theta)
        theta = theta + np.linalg.solve(kinematics.jacobian(gen, theta), err)
    return theta


@pytest.mark.parametrize(
    "frame",
    [
        bytes([6]) + struct.pack("<2f", 1.0, 2.0),
        bytes([5]) + struct.pack("<f", 1.0),
        bytes([5]) + struct.pack("<2f", float("nan"), 2.0),
    ],
)
def test_foreign_short_and_non_finite_frames_are_rejected(frame):
    with pytest.raises(protocol.BadFrame):
        protocol.decode_angles(frame, 5, 2)


def test_the_device_string_names_the_generation():
    assert create("/dev/ttyACM0").generation is GENERATIONS["gen3"]
    assert create("gen2:/dev/ttyACM0").generation is GENERATIONS["gen2"]
    assert create("gen2:/dev/ttyACM0").port == "/dev/ttyACM0"
