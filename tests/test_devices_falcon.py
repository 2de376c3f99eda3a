"""Novint Falcon: the wire format and the Stamper kinematics against values computed here
from libnifalcon's published equations and constants, then the driver in closed loop
against the emulated Falcon (tests/emulators/falcon_*.py, written from libnifalcon only).

libnifalcon = github.com/libnifalcon/libnifalcon at commit f7c727a.
"""

from __future__ import annotations

import math
import os
import time

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from sasprobe.devices.base import DeviceFault, DeviceOpenError
from sasprobe.devices.falcon import FalconDevice
from sasprobe.devices.falcon import kinematics as K
from sasprobe.devices.falcon import models as M
from sasprobe.devices.falcon import protocol as P
from tests.conftest import run_cli
from tests.emulators.falcon_device import FalconHardware, Hand
from tests.emulators.falcon_usb import EmulatedUsbBackend, launch

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
        common = w * w + u * u + 2 * c * u + a * a + c * c - d * d - e * e - sb * sb - 2 * sb * e - 2 * sb * d - 2 * d * e
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
        rows.append([(math.cos(phy) * math.cos(t2) * math.sin(t3) - math.sin(phy) * math.cos(t3)) / den,
                     (math.sin(phy) * math.cos(t2) * math.sin(t3) + math.cos(phy) * math.cos(t3)) / den,
                     math.sin(t2) * math.sin(t3) / den])
    return np.linalg.inv(np.array(rows))


def centre_line_z(theta1):
    """With every thigh at θ1 the grip is on the axis; its z in closed form."""
    u, v = -r + c, -s + f
    reach = d + e + math.sqrt(b * b - v * v)
    return a * math.sin(theta1) + math.sqrt(reach ** 2 - (u - a * math.cos(theta1)) ** 2)


CENTRE = np.array([0.0, 0.0, 0.110])  # FalconSphereTest.cpp: pos[2] -= 0.11

# --- wire format ----------------------------------------------------------------------------


def test_command_frame_is_libnifalcons_format_input():
    # formatInput: '<', each motor value's nibbles low first, byte 13 = LEDs | homing 0x01,
    # byte 14 = 0, every byte + 0x41, '>'
    frame = P.encode_command([0x1234, -1, 0], P.LED_RED, homing=True)
    assert frame == b"<" + bytes([0x41 + 4, 0x41 + 3, 0x41 + 2, 0x41 + 1]) + b"PPPPAAAA" + bytes([0x41 + 9]) + b"A>"
    assert P.encode_command([0, 0, 0], P.LED_GREEN, homing=True)[13] == 0x41 + 0x2 + 0x1


def test_reply_of_a_homed_falcon_is_accepted():
    # formatOutput: homing = ((byte13 - 0x41) >> 4) & 7, buttons = (byte13 - 0x41) & 0xf.
    # The header's own example: 'J','F','K','P' → 0xFA59 → -1447.
    status = 0x70 | 0x05  # all three axes homed, buttons 1 and 3
    frame = b"<JFKP" + b"AAAA" + b"PPPP" + bytes([0x41 + status]) + b"A>"
    assert frame[13] > ord("P")  # not a nibble byte
    assert P.decode_reply(frame) == P.Reply((-1447, 0, -1), 0b111, 0b101)


@settings(max_examples=300, deadline=None)
@given(st.lists(st.integers(-32768, 32767), min_size=3, max_size=3), st.integers(0, 7), st.integers(0, 15))
def test_replies_decode_whatever_the_values(encoders, homed, buttons):
    body = [((v & 0xFFFF) >> (4 * k)) & 0xF for v in encoders for k in range(4)]
    frame = bytes([0x3C, *(n + 0x41 for n in body), 0x41 + (homed << 4 | buttons), 0x41, 0x3E])
    assert P.decode_reply(frame) == P.Reply(tuple(encoders), homed, buttons)


@pytest.mark.parametrize("bad", [
    b"<AAAAAAAAAAAAAA",  # 15 bytes
    b"<AAAAAAAAAAAAAAA>",  # 17 bytes
    b"[AAAAAAAAAAAAAA>",
    b"<AAAAAAAAAAAAAA]",
    b"<AAAAAAAQAAAAAA>",  # 'Q' is no nibble
    b"<AAAAAAA@AAAAAA>",
    b"<AAAAAAAAAAAA\xc1A>",  # status past the seven bits
])
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
    assert replies == [P.Reply((1, 2, 3), 0b001, 0)] * 3
    assert reader.rejected == 3


# --- kinematics: known answers --------------------------------------------------------------

ENCODER_READINGS = [(0, 0, 0), (-516, -516, -516), (100, -200, 300), (-1000, 500, 250), (1500, 1500, -400),
                    (-300, -900, 700)]


def test_encoder_counts_to_thigh_angles_is_get_theta():
    for counts in ENCODER_READINGS:
        np.testing.assert_allclose(np.degrees(K.thigh_angles(counts)), [get_theta_deg(n) for n in counts],
                                   rtol=1e-12)


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
        (centre_line_z(math.radians(35.0)) - 0.110) * 1000.0)


def test_the_leg_rotation_is_in_the_geometry():
    # legs at 90°, -30°, -150°, each turned +15° (FalconGeometry.h OFFSET_ANGLE): a pure x
    # move stays a pure x move only with the rotation the IK assumes
    p = CENTRE + [0.020, 0.0, 0.0]
    theta = [t1 for t1, _, _ in stamper_ik(p)]
    np.testing.assert_allclose(K.to_device_mm(K.forward(theta)), [20.0, 0.0, 0.0], atol=1e-6)


@pytest.mark.parametrize("position_mm, force_n", [
    ((0, 0, 0), (0, 0, 1)), ((0, 0, 0), (1, 0, 0)), ((0, 0, 0), (0, 1, 0)),
    ((10, -5, 20), (2, -1, 3)), ((-30, 25, -15), (-1.5, 0.5, 2.0)), ((35, 35, 35), (0.5, 0.5, -0.5)),
])
def test_force_to_motor_commands_is_getforces(position_mm, force_n):
    p = CENTRE + np.asarray(position_mm) / 1000.0
    torque = stamper_jacobian(p).T @ np.asarray(force_n, dtype=float)
    expected = [int(-10000.0 * t) for t in torque]  # getForces: -(torque * 10000), as int
    assert K.motor_commands(K.jacobian(p), force_n) == expected


def test_motor_signs_match_the_traced_novint_packets():
    # util/translate_packet.py: commands the Novint driver sent for +x, -x and -z
    j_centre = K.jacobian(K.from_device_mm([0, 0, 0]))
    assert np.sign(K.motor_commands(j_centre, [1.0, 0, 0])).tolist() == [-1, 1, -1]  # [-65, 136, -159]
    assert np.sign(K.motor_commands(j_centre, [-5.0, 0, 0])).tolist() == [1, -1, 1]  # [399, -3087, 1135]
    assert np.sign(K.motor_commands(j_centre, [0, 0, -5.0])).tolist() == [1, 1, 1]  # [661, 731, 766]


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
        np.testing.assert_allclose(K.to_device_mm(K.forward([t for t, _, _ in stamper_ik(p)])), corner, atol=1e-6)


# --- the driver against the emulated Falcon -------------------------------------------------

ZERO = np.zeros(3)


def run_loop(dev, seconds, force_of=None):
    """The daemon's loop in miniature: read, force, write at about 1 kHz; faults collected."""
    states, faults = [], []
    end = time.monotonic() + seconds
    while time.monotonic() < end:
        force = ZERO
        try:
            state = dev.read()
            states.append(state)
            if force_of is not None:
                force = force_of(state)
        except DeviceFault as exc:
            faults.append(str(exc))
        dev.write_force(force)
        time.sleep(0.001)
    return states, faults


def loop_until(dev, condition, timeout_s=10.0):
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        states, _ = run_loop(dev, 0.02)
        if states and condition(states[-1]):
            return states[-1]
    raise AssertionError("condition not reached in time")


@pytest.fixture
def firmware(tmp_path):
    image = os.urandom(700)  # not a multiple of the 62-byte chunks
    path = tmp_path / "falcon_firmware.bin"
    path.write_bytes(image)
    return path, image


def make_rig(firmware, **options):
    path, image = firmware
    hand = Hand(homes=False)
    hw = FalconHardware(image, hand=hand, **options)
    hand.hardware = hw
    return FalconDevice(path, usb_backend=EmulatedUsbBackend(hw)), hw, hand


@pytest.fixture
def rig(firmware):
    dev, hw, hand = make_rig(firmware)
    yield dev, hw, hand
    dev.close()


def home(dev, hand):
    hand.homes = True
    state = loop_until(dev, lambda s: s.calibrated)
    hand.homes = False
    run_loop(dev, 0.3)  # back to the target
    return state


@pytest.mark.parametrize("macos", [False, True])
def test_upload_takes_the_loader_reply_of_either_platform_after_some_probes(firmware, macos):
    dev, hw, _hand = make_rig(firmware, probes_ignored=5, macos=macos)
    dev.open()
    try:
        assert hw.running and hw.probes_seen == 6 and hw.upload_attempts == 1 and dev.firmware_uploads == 1
        dev.read()
        dev.close()
        dev.open()  # the firmware is running now: nothing is uploaded again
        assert dev.firmware_uploads == 1 and hw.upload_attempts == 1
    finally:
        dev.close()


def test_a_bad_echo_retries_the_upload(firmware):
    dev, hw, _hand = make_rig(firmware, corrupt_echo_attempts={1})
    dev.open()
    assert dev.upload_retries == 1 and hw.upload_attempts == 2 and hw.running
    dev.close()


def test_a_loader_that_never_answers_is_one_clear_error_soon(firmware):
    dev, hw, _hand = make_rig(firmware, loader_silent=True)
    t0 = time.monotonic()
    with pytest.raises(DeviceOpenError, match="loader did not answer 100 probes") as err:
        dev.open()
    assert "\n" not in str(err.value) and time.monotonic() - t0 < 10.0
    assert hw.probes_seen == 100 and not dev._usb.is_open


def test_the_wrong_firmware_and_no_firmware_are_reported(firmware, tmp_path):
    _path, image = firmware
    wrong = tmp_path / "other.bin"
    wrong.write_bytes(os.urandom(256))
    with pytest.raises(DeviceOpenError, match="did not start after the firmware upload"):
        FalconDevice(wrong, usb_backend=EmulatedUsbBackend(FalconHardware(image))).open()
    with pytest.raises(DeviceOpenError, match="no firmware running"):
        FalconDevice(None, usb_backend=EmulatedUsbBackend(FalconHardware(image))).open()
    with pytest.raises(DeviceOpenError, match="firmware file not found"):
        FalconDevice(tmp_path / "nope.bin", usb_backend=EmulatedUsbBackend(FalconHardware(image))).open()
    absent = FalconHardware(image)
    absent.unplug()
    with pytest.raises(DeviceOpenError, match="no Novint Falcon found"):
        FalconDevice(wrong, usb_backend=EmulatedUsbBackend(absent)).open()


def test_homing_gates_force_and_the_homing_bit_stays(rig):
    dev, hw, hand = rig
    dev.open()
    run_loop(dev, 0.05, force_of=lambda s: np.array([0.0, 3.0, 0.0]))
    assert hw.motor == (0, 0, 0) and hw.leds == P.LED_RED and hw.homing
    assert not dev.read().calibrated
    home(dev, hand)
    states, _faults = run_loop(dev, 0.3, force_of=lambda s: np.array([0.0, 3.0, 0.0]))
    assert states[-1].calibrated and hw.motor != (0, 0, 0) and hw.leds == P.LED_GREEN and hw.homing
    assert hw.homing_losses == 0 and hw.refused == 0


def test_each_axis_and_a_diagonal_are_reported_as_moved(rig):
    dev, hw, hand = rig
    dev.open()
    home(dev, hand)
    hand.target = (0.0, 0.0, 0.0)
    states, _ = run_loop(dev, 0.4)
    origin = states[-1].position_mm
    for move in [(10, 0, 0), (-10, 0, 0), (0, 10, 0), (0, -10, 0), (0, 0, 10), (0, 0, -10), (7, -7, 7)]:
        hand.target = move
        states, _faults = run_loop(dev, 0.5)
        np.testing.assert_allclose(hw.stylus.position, move, atol=0.05)  # the hand holds it there
        np.testing.assert_allclose(states[-1].position_mm - origin, move, atol=0.5)
        np.testing.assert_allclose(states[-1].position_mm, hw.stylus.position, atol=0.1)
    assert hw.refused == 0 and hw.homing_losses == 0


def test_the_motors_exert_the_force_asked_for(rig):
    dev, hw, hand = rig
    dev.open()
    home(dev, hand)
    for where, force in [((0, 0, 0), (0, 0, 2.0)), ((0, 0, 0), (0, 0, -2.0)), ((15, -10, 5), (1.0, 2.0, -3.0)),
                         ((-20, 20, -20), (-2.5, 0.5, 1.5)), ((25, 5, 25), (3.0, -3.0, 0.0))]:
        hand.target = where
        run_loop(dev, 0.4)
        run_loop(dev, 0.05, force_of=lambda s: np.asarray(force))
        exerted = hw.samples[-1].force_n
        cosine = exerted @ force / np.linalg.norm(exerted) / np.linalg.norm(force)
        assert cosine >= 0.999, (where, force, exerted)
        assert np.linalg.norm(exerted) == pytest.approx(np.linalg.norm(force), rel=0.01)


def test_forces_never_exceed_the_declared_limit(firmware):
    dev, hw, hand = make_rig(firmware, hand_stiffness_n_per_mm=5.0)  # a firm grip
    dev.open()
    home(dev, hand)
    rng = np.random.default_rng(7)
    commands = [rng.normal(size=3) * 100.0 for _ in range(100)] + [[np.nan, 1.0, 1.0], [np.inf, 0, 0], [1e300] * 3]
    for command in commands:
        assert max(abs(m) for m in dev.motor_command(command)) <= M.MOTOR_COMMAND_LIMIT
        run_loop(dev, 0.003, force_of=lambda s: np.asarray(command, dtype=float))
        # thrown about by 8 N reversals the grip moves up to a millimetre between the reply
        # a command is computed from and the command's arrival; the force of fixed motor
        # commands changes by about 1 % per mm there
        assert np.linalg.norm(hw.samples[-1].force_n) <= M.FALCON_LIMITS.max_force_n * 1.02
    run_loop(dev, 0.01, force_of=lambda s: np.array([np.nan] * 3))
    dev.close()
    assert hw.motor == (0, 0, 0) and hw.refused == 0


def test_a_virtual_wall_settles_where_the_springs_balance(rig):
    dev, hw, hand = rig
    dev.open()
    home(dev, hand)
    hand.target = (20.0, 0.0, 0.0)

    def wall(state):  # 1 N/mm beyond x = 10 mm
        return np.array([-1.0 * max(state.position_mm[0] - 10.0, 0.0), 0.0, 0.0])

    states, faults = run_loop(dev, 1.5, force_of=wall)
    expected = (hw.stylus.hand_k * 20.0 + 1.0 * 10.0) / (hw.stylus.hand_k + 1.0)
    assert np.mean([s.position_mm[0] for s in states[-100:]]) == pytest.approx(expected, abs=0.3)


def test_a_200_ms_stall_is_survived_with_fresh_reads_after(rig):
    dev, hw, hand = rig
    dev.open()
    home(dev, hand)
    hand.target = (5.0, 5.0, 5.0)
    run_loop(dev, 0.3)
    hw.stall(0.2)
    hand.target = (-5.0, 0.0, 10.0)  # the hand moves on meanwhile
    t0 = time.monotonic()
    states, faults = run_loop(dev, 0.2)
    assert faults and all("has not answered" in f for f in faults)
    assert time.monotonic() - t0 < 0.5  # no read waited for the Falcon
    states, faults = run_loop(dev, 0.6)  # it answers again: the faults end by themselves
    assert len(states) > 100 and all("has not answered" in f for f in faults)
    assert hw.refused == 0 and hw.homing_losses == 0
    rng = np.random.default_rng(3)
    for _ in range(15):  # every read from now on describes the grip as the newest reply does
        hand.target = tuple(rng.uniform(-15.0, 15.0, size=3))
        run_loop(dev, 0.04)  # the grip is on its way there
        time.sleep(0.005)  # no frame goes out meanwhile: the reply to the last one is in
        state = dev.read()
        moved = np.linalg.norm(hw.samples[-1].grip_mm - hw.samples[-2].grip_mm)
        assert moved > 0.05  # a read one reply behind would be off by this much
        np.testing.assert_allclose(state.position_mm, hw.stylus.position, atol=0.05)


def test_a_falcon_that_stops_answering_faults_with_zero_force_and_no_hang(rig):
    dev, hw, hand = rig
    dev.open()
    home(dev, hand)
    run_loop(dev, 0.1, force_of=lambda s: np.array([0.0, 0.0, 2.0]))
    hw.hung = True
    states, faults = run_loop(dev, 0.1, force_of=lambda s: np.array([0.0, 0.0, 2.0]))
    assert faults and len(set(f.split(" for ")[0] for f in faults)) == 1 and "\n" not in faults[-1]
    assert dev.motor == [0, 0, 0]  # what it sends while silent
    probes = hw.probes_seen
    t0 = time.monotonic()
    with pytest.raises(DeviceFault, match="still unavailable.*USB link is up"):
        dev.reconnect()
    assert time.monotonic() - t0 < 0.1 and hw.probes_seen == probes  # no firmware reload into it


def test_pulling_the_cable_faults_at_once_and_recovers(rig):
    dev, hw, hand = rig
    dev.open()
    home(dev, hand)
    hw.unplug()
    states, faults = run_loop(dev, 0.05)
    assert faults and "USB link failed" in faults[-1]
    with pytest.raises(DeviceFault, match="still unavailable"):
        dev.reconnect()
    hw.replug()  # a freshly powered Falcon: loader mode, not homed
    dev.reconnect()
    assert dev.firmware_uploads == 2 and not dev.read().calibrated
    home(dev, hand)


def test_malformed_replies_are_counted_and_skipped(rig):
    dev, hw, hand = rig
    dev.open()
    home(dev, hand)
    injected = [b"\x00\x13junk", b"<AAAAAAAZAAAAAA>", b"<AAAAAAAAAAAAAAAAAA>", b"<AAAA", b"[AAAAAAAAAAAAAA>"]
    before = dev.rejected_frames
    for bad in injected:
        hw.inject_before_reply = [bad]
        states, _ = run_loop(dev, 0.02)
        np.testing.assert_allclose(states[-1].position_mm, hw.stylus.position, atol=0.1)
    assert dev.rejected_frames - before == len(injected)
    assert dev.info.details["rejected_frames"] == dev.rejected_frames


def test_buttons_come_through(rig):
    dev, hw, _hand = rig
    dev.open()
    hw.buttons = 0b0101
    states, _ = run_loop(dev, 0.02)
    assert states[-1].buttons == 0b0101


# --- through the CLI ------------------------------------------------------------------------

@pytest.mark.parametrize("options, with_firmware, message", [
    ({"loader_silent": True}, True, "loader did not answer 100 probes"),
    ({}, False, "no firmware running"),
])
def test_cli_reports_a_falcon_it_cannot_start_in_one_line(options, with_firmware, message):
    emu = launch(**options)
    try:
        spec = emu.device_spec if with_firmware else "falcon"
        result = run_cli("devices", "--check", spec, env=dict(os.environ, **emu.env), timeout=60)
    finally:
        emu.close()
    assert result.returncode == 2, result.stderr
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and message in lines[0] and "Traceback" not in result.stderr
