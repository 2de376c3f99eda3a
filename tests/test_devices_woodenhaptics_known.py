"""WoodenHaptics/Polhem: known answers computed here from hfabapi's equations and
constants, and the firmware's line protocol (the driver against the emulated board is in
test_devices_woodenhaptics.py)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from sasprobe.devices.woodenhaptics import kinematics, protocol
from sasprobe.devices.woodenhaptics.models import WOODEN_MODELS

# --- known answers -----------------------------------------------------------------------
# Constants transcribed for this test from forsslund/hfabapi cf00e97 (hfab_math.h
# configurations polhem_v3, vintage, woodenhaptics_v2015; hfab_api.cpp enc_home_*):
# capstan ∅, body ∅, motor_and_body_aligned, cpr, home counts, (Ln, Lb, Lc), origin, Kt.
HFAB = {
    1: dict(
        cap=(0.0288534, 0.0136981, 0.0137281),
        body=(0.175, 0.100, 0.100),
        aligned=(0, 1, 0),
        cpr=(4096, 4096, 4096),
        home=(8312, -10366, 19764, 0, 30, 0),
        links=None,
        origin=(0.2045, 0.0, 0.0325),
        kt=(0.0603, 0.0538, 0.0538),
    ),
    2: dict(
        cap=(0.013, 0.010, 0.010),
        body=(0.117, 0.077, 0.077),
        aligned=(1, 0, 1),
        cpr=(4000, 4000, 4000),
        home=(0, 7700, 0, 0, 0, 0),
        links=(0.000, 0.138, 0.112),
        origin=(0.138, 0.000, -0.097),
        kt=(0.0234, 0.0234, 0.0234),
    ),
    3: dict(
        cap=(0.010, 0.010, 0.010),
        body=(0.160, 0.120, 0.120),
        aligned=(0, 1, 1),
        cpr=(2000, 2000, 2000),
        home=(0, 0, -6000, 0, 0, 0),
        links=(0.080, 0.205, 0.245),
        origin=(0.220, 0.000, 0.080),
        kt=(0.0259, 0.0259, 0.0259),
    ),
}
POLHEM_L = (34e-3, 165e-3, 25e-3, 190e-3, 34e-3, 130.8e-3)  # hfab_polhem.h L0..L5
COUNTS = {
    1: [(0, 0, 0), (-1500, 900, -2000), (700, -400, 1200), (-300, 2500, -600)],
    2: [(0, 0, 0), (500, -700, 300), (-800, 400, -900), (1200, 1500, 600)],
    3: [(0, 0, 0), (250, -400, 1000), (-500, 300, 2000), (1200, 800, 2500)],
}


def hfab_angles(c, raw):
    """calculate_pose(): the received counts plus enc_home, through the capstans."""
    enc = [raw[i] + c["home"][i] for i in range(3)]
    return [
        (-1.0 if c["aligned"][i] else 1.0)
        * 2
        * math.pi
        * enc[i]
        / c["cpr"][i]
        * c["cap"][i]
        / c["body"][i]
        for i in range(3)
    ]


def polhem_kinematics(t1, t2, t3):
    """polhemKinematics() as hfab_polhem.h writes it."""
    l0, l1, l2, l3, l4, l5 = POLHEM_L
    a = l0 + l1 * math.cos(t2)
    sq1, sq2 = (a - l2 * math.cos(t3)) ** 2, (l1 * math.sin(t2) - l2 * math.sin(t3)) ** 2
    sq3, sq4 = a * a, (l1 * math.sin(t2)) ** 2
    sqrt1, sqrt2 = math.sqrt(sq1 + sq2), math.sqrt(sq3 + sq4)
    x1, x2, x3, x4 = 2 * sqrt2 * sqrt1, -(l3**2) + l4**2 + sq1 + sq2, 2 * l1 * sqrt2, 2 * l4 * sqrt1
    x5, x6 = -(l0**2) + l1**2 + sq3 + sq4, -(l2**2) + sq1 + sq2 + sq3 + sq4
    y1 = t2 - math.acos(x5 / x3) - math.acos(x2 / x4) - math.acos(x6 / x1)
    x7 = l0 / 2 + l1 * math.cos(t2) + l5 * math.cos(y1)
    return [x7 * math.cos(t1), x7 * math.sin(t1), l1 * math.sin(t2) + l5 * math.sin(y1)], y1


def hfab_position(code, t):
    """computePosition(): metres, x toward the user, y right, z up, minus the origin."""
    c = HFAB[code]
    if c["links"] is None:
        p = polhem_kinematics(*t)[0]
    else:
        ln, lb, lc = c["links"]
        p = [
            math.cos(t[0]) * (lb * math.sin(t[1]) + lc * math.sin(t[2])),
            math.sin(t[0]) * (lb * math.sin(t[1]) + lc * math.sin(t[2])),
            ln + lb * math.cos(t[1]) - lc * math.cos(t[2]),
        ]
    return [p[i] - c["origin"][i] for i in range(3)]


def hfab_amps(code, force_hfab, t):
    """computeMotorAmps() without gravity (g_constant 0; Polhem's gravity term not sent by us)."""
    c = HFAB[code]
    fx, fy, fz = force_hfab
    ta, tb, tc = t
    if c["links"] is None:
        h = 0.00001
        jac = []
        for i in range(3):
            plus, minus = list(t), list(t)
            plus[i] += h / 2
            minus[i] -= h / 2
            jac.append(
                [
                    (a - b) / h
                    for a, b in zip(polhem_kinematics(*plus)[0], polhem_kinematics(*minus)[0])
                ]
            )
        tau = [sum(jac[i][k] * force_hfab[k] for k in range(3)) for i in range(3)]
    else:
        _ln, lb, lc = c["links"]
        r = lb * math.sin(tb) + lc * math.sin(tc)
        tau = [
            -math.sin(ta) * r * fx + math.cos(ta) * r * fy,
            lb * math.cos(ta) * math.cos(tb) * fx
            + lb * math.sin(ta) * math.cos(tb) * fy
            - lb * math.sin(tb) * fz,
            lc * math.cos(ta) * math.cos(tc) * fx
            + lc * math.sin(ta) * math.cos(tc) * fy
            + lc * math.sin(tc) * fz,
        ]
    return [
        tau[i] * (-1.0 if c["aligned"][i] else 1.0) * c["cap"][i] / c["body"][i] / c["kt"][i]
        for i in range(3)
    ]


@pytest.mark.parametrize("code", [1, 2, 3])
def test_tip_positions_match_hfabapi_at_known_counts(code):
    model = WOODEN_MODELS[code]
    for raw in COUNTS[code]:
        t = hfab_angles(HFAB[code], raw)
        x, y, z = hfab_position(code, t)
        expected = [
            1000 * y,
            1000 * z,
            1000 * x,
        ]  # device X right = hfab y, Y up = z, Z toward the user = x
        angles = kinematics.body_angles(model, raw + (0, 0, 0))
        np.testing.assert_allclose(angles, t, atol=1e-12)
        np.testing.assert_allclose(
            kinematics.tip_position_mm(model, angles)[0], expected, atol=1e-9
        )


@pytest.mark.parametrize("code", [1, 2, 3])
def test_force_to_current_matches_hfabapi_at_known_counts(code):
    model = WOODEN_MODELS[code]
    for raw in COUNTS[code]:
        t = hfab_angles(HFAB[code], raw)
        for force in ([1.0, 0.0, 0.0], [0.0, -2.0, 0.5], [0.7, 1.1, -1.6]):
            expected_ma = [a * 1000 for a in hfab_amps(code, [force[2], force[0], force[1]], t)]
            got = kinematics.motor_currents_ma(
                model, kinematics.body_angles(model, raw + (0, 0, 0)), force
            )
            np.testing.assert_allclose(got, expected_ma, atol=0.05)


def test_currents_beyond_the_firmware_range_are_scaled_together():
    model = WOODEN_MODELS[3]
    raw = (250, -400, 1000)
    t = hfab_angles(HFAB[3], raw)
    force = [40.0, -60.0, 30.0]  # far beyond what ±6000 mA gives
    expected = np.array(hfab_amps(3, [force[2], force[0], force[1]], t)) * 1000
    got = kinematics.motor_currents_ma(model, kinematics.body_angles(model, raw + (0, 0, 0)), force)
    assert np.max(np.abs(got)) == pytest.approx(
        protocol.MAX_CURRENT_MA
    )  # the firmware zeroes anything beyond
    np.testing.assert_allclose(
        got / np.linalg.norm(got), expected / np.linalg.norm(expected), atol=1e-12
    )


def rotation_of(q) -> np.ndarray:
    w, x, y, z = q
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
            [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
            [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
        ]
    )


def rx(t):
    return np.array([[1, 0, 0], [0, math.cos(t), -math.sin(t)], [0, math.sin(t), math.cos(t)]])


def ry(t):
    return np.array([[math.cos(t), 0, math.sin(t)], [0, 1, 0], [-math.sin(t), 0, math.cos(t)]])


def rz(t):
    return np.array([[math.cos(t), -math.sin(t), 0], [math.sin(t), math.cos(t), 0], [0, 0, 1]])


@pytest.mark.parametrize("code, gimbal", [(1, (100, -200, 300)), (2, (150, 400, -250))])
def test_stylus_orientation_follows_hfabapi_getrot(code, gimbal):
    model = WOODEN_MODELS[code]
    raw = COUNTS[code][1] + gimbal
    enc = [raw[i] + HFAB[code]["home"][i] for i in range(6)]
    t = hfab_angles(HFAB[code], raw)
    if code == 1:  # Polhem: cpr_d..f 1024, enc_and_body_aligned d, e = 0; λ from the position
        lam = polhem_kinematics(*t)[1]
        r = (
            rz(t[0])
            @ ry(-lam)
            @ rx(-enc[3] * 2 * math.pi / 1024)
            @ ry(-enc[4] * 2 * math.pi / 1024)
            @ rx(2 * math.pi * enc[5] / 1024)
        )
    else:  # vintage: 2000 counts, d about z, enc_and_body_aligned d = 0, e = 1; no λ
        r = (
            rz(t[0])
            @ rz(-enc[3] * 2 * math.pi / 2000)
            @ ry(enc[4] * 2 * math.pi / 2000)
            @ rx(2 * math.pi * enc[5] / 2000)
        )
    swap = np.array(
        [[0, 1, 0], [0, 0, 1], [1, 0, 0]]
    )  # hfab (x, y, z) → device (X, Y, Z) = (y, z, x)
    angles = kinematics.body_angles(model, raw)
    lam_driver = kinematics.tip_position_mm(model, angles)[1]
    got = rotation_of(kinematics.orientation(model, angles, lam_driver, raw))
    np.testing.assert_allclose(got, swap @ r @ swap.T, atol=1e-9)


def test_woody_reports_no_orientation():
    model = WOODEN_MODELS[3]
    q = kinematics.orientation(model, np.zeros(3), 0.0, (0, 0, 0, 11, 22, 33))
    assert q.tolist() == [1.0, 0.0, 0.0, 0.0]


# --- the line protocol ---------------------------------------------------------------------


def test_command_and_reply_lines_follow_the_firmware():
    assert protocol.encode_command([12.4, -300.0, 0.0]) == b"[12,-300,0]\n"
    reply = protocol.parse_reply(b"[3,10,-20,30,1,2,3,0]")
    assert (reply.model, reply.counts, reply.error, reply.refused) == (
        3,
        (10, -20, 30, 1, 2, 3),
        0,
        False,
    )
    assert protocol.parse_reply(b"[1,0,0,0,0,0,0,8]\r").refused
    assert not protocol.parse_reply(
        b"[1,0,0,0,0,0,0,2]"
    ).refused  # a gimbal sensor, not our command


@pytest.mark.parametrize(
    "line",
    [
        b"3,0,0,0,0,0,0,0]",
        b"[3,0,0,0,0,0,0,0",
        b"[3,0,0,0]",
        b"[3,0,0,0,0,0,0,0,0]",
        b"[3,x,0,0,0,0,0,0]",
        b"[3,0.5,0,0,0,0,0,0]",
        b"\xff\xfe",
        b"",
    ],
)
def test_malformed_reply_lines_are_rejected(line):
    with pytest.raises(protocol.BadFrame):
        protocol.parse_reply(line)


def test_error_bits_are_named():
    assert protocol.describe_errors(512 | 2) == "gimbal sensor 1 unread, wrong number of currents"
    assert protocol.describe_errors(0) == "none"
