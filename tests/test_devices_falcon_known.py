"""Novint Falcon: the wire format and the Stamper kinematics against values computed here
from libnifalcon's published equations and constants (the driver against the emulated
Falcon is in test_devices_falcon.py).

libnifalcon = github.com/libnifalcon/libnifalcon at commit f7c727a.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from sasprobe.devices.falcon import kinematics as K
from sasprobe.devices.falcon import models as M
from sasprobe.devices.falcon import protocol as P

# --- libnifalcon's published equations, written out here ------------------------------------

# FalconGeometry.h (metres) and FalconKinematic.h getTheta
a, b, c, d, e, f, r, s = 0.060, 0.1025, 0.01443, 0.01125, 0.01125, -0.025, 0.0400, -0.02309
PHY = [math.pi / 2 + math.pi / 12, -math.pi / 6 + math.pi / 12, -5 * math.pi / 6 + math.pi / 12]


def get_theta_deg(count):
    return ((0.01425 * math.pi) / (320 * 4) * count) / ((math.pi * 0.110) / 360.0) + 35.0


def stamper_ik(p):
    """FalconKinematicStamper.cpp IK: θ1 from the tan-half-angle quadratic (its T1b root)."""
    out = []
    for phy in PHY:
        u = math.cos(phy) * p[0] + math.sin(phy) * p[1] - r
        v = -math.sin(phy) * p[0] + math.cos(phy) * p[1] - s
        w = p[2]
        t3 = math.acos((v + f) / b)
        sb = b * math.sin(t3)
        common = (
            w * w
            + u * u
            + 2 * c * u
            + a * a
            + c * c
            - d * d
            - e * e
            - sb * sb
            - 2 * sb * e
            - 2 * sb * d
            - 2 * d * e
        )
        l0, l1, l2 = common - 2 * a * u - 2 * a * c, -4 * a * w, common + 2 * a * u + 2 * a * c
        t1 = 2 * math.atan((-l1 - math.sqrt(l1 * l1 - 4 * l0 * l2)) / (2 * l2))
        t2 = math.acos((-u + a * math.cos(t1) - c) / (-d - e - sb))
        out.append((t1, t2, t3))
    return out


def stamper_jacobian(p):
    """∂p/∂θ1 from Stamper's joint rates (the thesis form: z entry sin θ2 · sin θ3)."""
    rows = []
    for phy, (t1, t2, t3) in zip(PHY, stamper_ik(p)):
        den = -a * math.sin(t3) * (math.sin(t1) * math.cos(t2) - math.sin(t2) * math.cos(t1))
        rows.append(
            [
                (math.cos(phy) * math.cos(t2) * math.sin(t3) - math.sin(phy) * math.cos(t3)) / den,
                (math.sin(phy) * math.cos(t2) * math.sin(t3) + math.cos(phy) * math.cos(t3)) / den,
                math.sin(t2) * math.sin(t3) / den,
            ]
        )
    return np.linalg.inv(np.array(rows))


def centre_line_z(theta1):
    """With every thigh at θ1 the grip is on the axis; its z in closed form."""
    u, v = -r + c, -s + f
    reach = d + e + math.sqrt(b * b - v * v)
    return a * math.sin(theta1) + math.sqrt(reach**2 - (u - a * math.cos(theta1)) ** 2)


CENTRE = np.array([0.0, 0.0, 0.110])  # FalconSphereTest.cpp: pos[2] -= 0.11

# --- wire format ----------------------------------------------------------------------------


def test_command_frame_is_libnifalcons_format_input():
    # formatInput: '<', each motor value's nibbles low first, byte 13 = LEDs | homing 0x01,
    # byte 14 = 0, every byte + 0x41, '>'
    frame = P.encode_command([0x1234, -1, 0], P.LED_RED, homing=True)
    assert (
        frame
        == b"<"
        + bytes([0x41 + 4, 0x41 + 3, 0x41 + 2, 0x41 + 1])
        + b"PPPPAAAA"
        + bytes([0x41 + 9])
        + b"A>"
    )
    assert P.encode_command([0, 0, 0], P.LED_GREEN, homing=True)[13] == 0x41 + 0x2 + 0x1


def test_reply_of_a_homed_falcon_is_accepted():
    # formatOutput: homing = ((byte13 - 0x41) >> 4) & 7, buttons = (byte13 - 0x41) & 0xf.
    # The header's own example: 'J','F','K','P' → 0xFA59 → -1447.
    status = 0x70 | 0x05  # all three axes homed, buttons 1 and 3
    frame = b"<JFKP" + b"AAAA" + b"PPPP" + bytes([0x41 + status]) + b"A>"
    assert frame[13] > ord("P")  # not a nibble byte
    assert P.decode_reply(frame) == P.FalconReply((-1447, 0, -1), 0b111, 0b101)


@settings(max_examples=300, deadline=None)
@given(
    st.lists(st.integers(-32768, 32767), min_size=3, max_size=3),
    st.integers(0, 7),
    st.integers(0, 15),
)
def test_replies_decode_whatever_the_values(encoders, homed, buttons):
    body = [((v & 0xFFFF) >> (4 * k)) & 0xF for v in encoders for k in range(4)]
    frame = bytes([0x3C, *(n + 0x41 for n in body), 0x41 + (homed << 4 | buttons), 0x41, 0x3E])
    assert P.decode_reply(frame) == P.FalconReply(tuple(encoders), homed, buttons)


@pytest.mark.parametrize(
    "bad",
    [
        b"<AAAAAAAAAAAAAA",  # 15 bytes
        b"<AAAAAAAAAAAAAAA>",  # 17 bytes
        b"[AAAAAAAAAAAAAA>",
        b"<AAAAAAAAAAAAAA]",
        b"<AAAAAAAQAAAAAA>",  # 'Q' is no nibble
        b"<AAAAAAA@AAAAAA>",
        b"<AAAAAAAAAAAA\xc1A>",  # status past the seven bits
    ],
)
def test_malformed_frames_are_rejected(bad):
    with pytest.raises(P.FrameError):
        P.decode_reply(bad)


def test_frame_reader_skips_and_counts_junk_and_bad_frames():
    good = b"<BAAACAAADAAA" + bytes([0x41 + 0x10]) + b"A>"
    reader = P.FrameReader()
    reader.feed(b"\x00junk" + good + b"<AAAAZAAAAAAAAA>" + good + b"<AAA" + good)
    replies = []
    while (reply := reader.next_reply()) is not None:
        replies.append(reply)
    assert replies == [P.FalconReply((1, 2, 3), 0b001, 0)] * 3
    assert reader.rejected == 3


# --- kinematics: known answers --------------------------------------------------------------

ENCODER_READINGS = [
    (0, 0, 0),
    (-516, -516, -516),
    (100, -200, 300),
    (-1000, 500, 250),
    (1500, 1500, -400),
    (-300, -900, 700),
]


def test_encoder_counts_to_thigh_angles_is_get_theta():
    for counts in ENCODER_READINGS:
        np.testing.assert_allclose(
            np.degrees(K.thigh_angles(counts)), [get_theta_deg(n) for n in counts], rtol=1e-12
        )


@pytest.mark.parametrize("counts", ENCODER_READINGS)
def test_encoders_give_the_position_whose_stamper_ik_they_are(counts):
    theta = np.radians([get_theta_deg(n) for n in counts])
    p = K.forward(theta)
    np.testing.assert_allclose([t1 for t1, _, _ in stamper_ik(p)], theta, atol=1e-9)


def test_equal_encoders_put_the_grip_on_the_axis():
    for n in (-1200, -516, 0, 700):
        theta = math.radians(get_theta_deg(n))
        p = K.forward([theta] * 3)
        np.testing.assert_allclose(p, [0.0, 0.0, centre_line_z(theta)], atol=1e-12)
    # with count 0 (35°, once homed) the grip is about 25 mm out of the centre, toward the user
    assert K.to_device_mm(K.forward(np.radians([35.0] * 3)))[2] == pytest.approx(
        (centre_line_z(math.radians(35.0)) - 0.110) * 1000.0
    )


def test_the_leg_rotation_is_in_the_geometry():
    # legs at 90°, -30°, -150°, each turned +15° (FalconGeometry.h OFFSET_ANGLE): a pure x
    # move stays a pure x move only with the rotation the IK assumes
    p = CENTRE + [0.020, 0.0, 0.0]
    theta = [t1 for t1, _, _ in stamper_ik(p)]
    np.testing.assert_allclose(K.to_device_mm(K.forward(theta)), [20.0, 0.0, 0.0], atol=1e-6)


@pytest.mark.parametrize(
    "position_mm, force_n",
    [
        ((0, 0, 0), (0, 0, 1)),
        ((0, 0, 0), (1, 0, 0)),
        ((0, 0, 0), (0, 1, 0)),
        ((10, -5, 20), (2, -1, 3)),
        ((-30, 25, -15), (-1.5, 0.5, 2.0)),
        ((35, 35, 35), (0.5, 0.5, -0.5)),
    ],
)
def test_force_to_motor_commands_is_getforces(position_mm, force_n):
    p = CENTRE + np.asarray(position_mm) / 1000.0
    torque = stamper_jacobian(p).T @ np.asarray(force_n, dtype=float)
    expected = [int(-10000.0 * t) for t in torque]  # getForces: -(torque * 10000), as int
    assert K.motor_commands(K.jacobian(p), force_n) == expected


def test_motor_signs_match_the_traced_novint_packets():
    # util/translate_packet.py: commands the Novint driver sent for +x, -x and -z
    j_centre = K.jacobian(K.from_device_mm([0, 0, 0]))
    assert np.sign(K.motor_commands(j_centre, [1.0, 0, 0])).tolist() == [
        -1,
        1,
        -1,
    ]  # [-65, 136, -159]
    assert np.sign(K.motor_commands(j_centre, [-5.0, 0, 0])).tolist() == [
        1,
        -1,
        1,
    ]  # [399, -3087, 1135]
    assert np.sign(K.motor_commands(j_centre, [0, 0, -5.0])).tolist() == [
        1,
        1,
        1,
    ]  # [661, 731, 766]


def test_commands_beyond_4096_are_scaled_together():
    p = K.from_device_mm([10, 20, -10])
    force = np.array([30.0, -12.0, 20.0])
    unlimited = -10000.0 * (stamper_jacobian(p).T @ force)
    motor = K.motor_commands(K.jacobian(p), force)
    assert max(abs(m) for m in motor) <= 4096
    np.testing.assert_allclose(motor, unlimited * 4096 / np.max(np.abs(unlimited)), atol=1.0)
    assert K.motor_commands(K.jacobian(p), [math.nan, 0, 0]) == [0, 0, 0]


def test_the_declared_workspace_is_reachable_and_well_conditioned():
    lo, hi = np.array(M.FALCON_LIMITS.workspace_min_mm), np.array(M.FALCON_LIMITS.workspace_max_mm)
    for corner in np.stack(np.meshgrid(*zip(lo, hi), indexing="ij"), -1).reshape(-1, 3):
        p = K.from_device_mm(corner)
        assert np.linalg.cond(stamper_jacobian(p)) < 5.0
        np.testing.assert_allclose(
            K.to_device_mm(K.forward([t for t, _, _ in stamper_ik(p)])), corner, atol=1e-6
        )
