"""WoodenHaptics/Polhem driver: known answers from hfabapi's equations, and closed loops
against the emulated Teensy firmware and mechanism behind a real pty."""

from __future__ import annotations

import math
import time

import numpy as np
import pytest

from sasprobe.devices.base import DeviceFault, DeviceOpenError
from sasprobe.devices.woodenhaptics import WoodenHapticsDevice, kinematics, protocol
from sasprobe.devices.woodenhaptics.models import WOODEN_MODELS
from tests.emulators import woodenhaptics_serial
from tests.emulators.pty_serial import PtySerialDevice
from tests.serial_arm_session import Session, cosine

# --- known answers -----------------------------------------------------------------------
# Constants transcribed for this test from forsslund/hfabapi cf00e97 (hfab_math.h
# configurations polhem_v3, vintage, woodenhaptics_v2015; hfab_api.cpp enc_home_*):
# capstan ∅, body ∅, motor_and_body_aligned, cpr, home counts, (Ln, Lb, Lc), origin, Kt.
HFAB = {
    1: dict(cap=(0.0288534, 0.0136981, 0.0137281), body=(0.175, 0.100, 0.100), aligned=(0, 1, 0),
            cpr=(4096, 4096, 4096), home=(8312, -10366, 19764, 0, 30, 0), links=None,
            origin=(0.2045, 0.0, 0.0325), kt=(0.0603, 0.0538, 0.0538)),
    2: dict(cap=(0.013, 0.010, 0.010), body=(0.117, 0.077, 0.077), aligned=(1, 0, 1), cpr=(4000, 4000, 4000),
            home=(0, 7700, 0, 0, 0, 0), links=(0.000, 0.138, 0.112), origin=(0.138, 0.000, -0.097),
            kt=(0.0234, 0.0234, 0.0234)),
    3: dict(cap=(0.010, 0.010, 0.010), body=(0.160, 0.120, 0.120), aligned=(0, 1, 1), cpr=(2000, 2000, 2000),
            home=(0, 0, -6000, 0, 0, 0), links=(0.080, 0.205, 0.245), origin=(0.220, 0.000, 0.080),
            kt=(0.0259, 0.0259, 0.0259)),
}
POLHEM_L = (34e-3, 165e-3, 25e-3, 190e-3, 34e-3, 130.8e-3)  # hfab_polhem.h L0..L5
COUNTS = {1: [(0, 0, 0), (-1500, 900, -2000), (700, -400, 1200), (-300, 2500, -600)],
          2: [(0, 0, 0), (500, -700, 300), (-800, 400, -900), (1200, 1500, 600)],
          3: [(0, 0, 0), (250, -400, 1000), (-500, 300, 2000), (1200, 800, 2500)]}


def hfab_angles(c, raw):
    """calculate_pose(): the received counts plus enc_home, through the capstans."""
    enc = [raw[i] + c["home"][i] for i in range(3)]
    return [(-1.0 if c["aligned"][i] else 1.0) * 2 * math.pi * enc[i] / c["cpr"][i] * c["cap"][i] / c["body"][i]
            for i in range(3)]


def polhem_kinematics(t1, t2, t3):
    """polhemKinematics() as hfab_polhem.h writes it."""
    l0, l1, l2, l3, l4, l5 = POLHEM_L
    a = l0 + l1 * math.cos(t2)
    sq1, sq2 = (a - l2 * math.cos(t3)) ** 2, (l1 * math.sin(t2) - l2 * math.sin(t3)) ** 2
    sq3, sq4 = a * a, (l1 * math.sin(t2)) ** 2
    sqrt1, sqrt2 = math.sqrt(sq1 + sq2), math.sqrt(sq3 + sq4)
    x1, x2, x3, x4 = 2 * sqrt2 * sqrt1, -l3 ** 2 + l4 ** 2 + sq1 + sq2, 2 * l1 * sqrt2, 2 * l4 * sqrt1
    x5, x6 = -l0 ** 2 + l1 ** 2 + sq3 + sq4, -l2 ** 2 + sq1 + sq2 + sq3 + sq4
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
        p = [math.cos(t[0]) * (lb * math.sin(t[1]) + lc * math.sin(t[2])),
             math.sin(t[0]) * (lb * math.sin(t[1]) + lc * math.sin(t[2])),
             ln + lb * math.cos(t[1]) - lc * math.cos(t[2])]
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
            jac.append([(a - b) / h for a, b in zip(polhem_kinematics(*plus)[0], polhem_kinematics(*minus)[0])])
        tau = [sum(jac[i][k] * force_hfab[k] for k in range(3)) for i in range(3)]
    else:
        _ln, lb, lc = c["links"]
        r = lb * math.sin(tb) + lc * math.sin(tc)
        tau = [-math.sin(ta) * r * fx + math.cos(ta) * r * fy,
               lb * math.cos(ta) * math.cos(tb) * fx + lb * math.sin(ta) * math.cos(tb) * fy - lb * math.sin(tb) * fz,
               lc * math.cos(ta) * math.cos(tc) * fx + lc * math.sin(ta) * math.cos(tc) * fy + lc * math.sin(tc) * fz]
    return [tau[i] * (-1.0 if c["aligned"][i] else 1.0) * c["cap"][i] / c["body"][i] / c["kt"][i] for i in range(3)]


@pytest.mark.parametrize("code", [1, 2, 3])
def test_tip_positions_match_hfabapi_at_known_counts(code):
    model = WOODEN_MODELS[code]
    for raw in COUNTS[code]:
        t = hfab_angles(HFAB[code], raw)
        x, y, z = hfab_position(code, t)
        expected = [1000 * y, 1000 * z, 1000 * x]  # device X right = hfab y, Y up = z, Z toward the user = x
        angles = kinematics.body_angles(model, raw + (0, 0, 0))
        np.testing.assert_allclose(angles, t, atol=1e-12)
        np.testing.assert_allclose(kinematics.tip_position_mm(model, angles)[0], expected, atol=1e-9)


@pytest.mark.parametrize("code", [1, 2, 3])
def test_force_to_current_matches_hfabapi_at_known_counts(code):
    model = WOODEN_MODELS[code]
    for raw in COUNTS[code]:
        t = hfab_angles(HFAB[code], raw)
        for force in ([1.0, 0.0, 0.0], [0.0, -2.0, 0.5], [0.7, 1.1, -1.6]):
            expected_ma = [a * 1000 for a in hfab_amps(code, [force[2], force[0], force[1]], t)]
            got = kinematics.motor_currents_ma(model, kinematics.body_angles(model, raw + (0, 0, 0)), force)
            np.testing.assert_allclose(got, expected_ma, atol=0.05)


def test_currents_beyond_the_firmware_range_are_scaled_together():
    model = WOODEN_MODELS[3]
    raw = (250, -400, 1000)
    t = hfab_angles(HFAB[3], raw)
    force = [40.0, -60.0, 30.0]  # far beyond what ±6000 mA gives
    expected = np.array(hfab_amps(3, [force[2], force[0], force[1]], t)) * 1000
    got = kinematics.motor_currents_ma(model, kinematics.body_angles(model, raw + (0, 0, 0)), force)
    assert np.max(np.abs(got)) == pytest.approx(protocol.MAX_CURRENT_MA)  # the firmware zeroes anything beyond
    np.testing.assert_allclose(got / np.linalg.norm(got), expected / np.linalg.norm(expected), atol=1e-12)


def rotation_of(q) -> np.ndarray:
    w, x, y, z = q
    return np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
                     [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
                     [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)]])


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
        r = rz(t[0]) @ ry(-lam) @ rx(-enc[3] * 2 * math.pi / 1024) @ ry(-enc[4] * 2 * math.pi / 1024) \
            @ rx(2 * math.pi * enc[5] / 1024)
    else:  # vintage: 2000 counts, d about z, enc_and_body_aligned d = 0, e = 1; no λ
        r = rz(t[0]) @ rz(-enc[3] * 2 * math.pi / 2000) @ ry(enc[4] * 2 * math.pi / 2000) \
            @ rx(2 * math.pi * enc[5] / 2000)
    swap = np.array([[0, 1, 0], [0, 0, 1], [1, 0, 0]])  # hfab (x, y, z) → device (X, Y, Z) = (y, z, x)
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
    assert (reply.model, reply.counts, reply.error, reply.refused) == (3, (10, -20, 30, 1, 2, 3), 0, False)
    assert protocol.parse_reply(b"[1,0,0,0,0,0,0,8]\r").refused
    assert not protocol.parse_reply(b"[1,0,0,0,0,0,0,2]").refused  # a gimbal sensor, not our command


@pytest.mark.parametrize("line", [b"3,0,0,0,0,0,0,0]", b"[3,0,0,0,0,0,0,0", b"[3,0,0,0]", b"[3,0,0,0,0,0,0,0,0]",
                                  b"[3,x,0,0,0,0,0,0]", b"[3,0.5,0,0,0,0,0,0]", b"\xff\xfe", b""])
def test_malformed_reply_lines_are_rejected(line):
    with pytest.raises(protocol.BadFrame):
        protocol.parse_reply(line)


def test_error_bits_are_named():
    assert protocol.describe_errors(512 | 2) == "gimbal sensor 1 unread, wrong number of currents"
    assert protocol.describe_errors(0) == "none"


# --- against the emulated board ---------------------------------------------------------------

@pytest.fixture
def rig(request):
    options = getattr(request, "param", {})
    rig = woodenhaptics_serial.launch(**options)
    dev = WoodenHapticsDevice(rig.board.path)
    yield dev, rig.board, rig.hand
    dev.close()
    rig.close()


MOVES = [(10, 0, 0), (-10, 0, 0), (0, 10, 0), (0, -10, 0), (0, 0, 10), (0, 0, -10), (7, -7, 7)]
FORCES = [(2.0, 0.0, 0.0), (0.0, -2.0, 0.0), (0.0, 0.0, 2.0), (1.5, 1.0, -2.0)]


def check_forces(session, board, forces) -> None:
    """The force the emulated motors exert is the force written (cos ≥ 0.99, within 5 %)."""
    for force in forces:
        session.run(0.02, force)
        made = board.motor_force()
        assert cosine(made, force) >= 0.99, (force, made)
        assert np.linalg.norm(made) == pytest.approx(np.linalg.norm(force), rel=0.05), (force, made)


@pytest.mark.parametrize("rig", [{"model": 1}, {"model": 2}, {"model": 3}], indirect=True,
                         ids=["polhem", "vintage", "woody"])
def test_displacements_and_forces_in_the_device_frame(rig):
    dev, board, hand = rig
    dev.open()
    session = Session(dev)
    home = session.until(lambda s: True)
    np.testing.assert_allclose(home.position_mm, board.stylus.now(), atol=0.5)  # the home pose, where counts are 0
    hand.target = (0.0, 0.0, 0.0)  # the workspace centre
    centre = session.settle(board.stylus, hand)
    np.testing.assert_allclose(centre.position_mm, board.stylus.now(), atol=0.5)
    centre_true = board.stylus.now()
    for move in MOVES:
        hand.target = move
        state = session.settle(board.stylus, hand)
        true_move = board.stylus.now() - centre_true
        np.testing.assert_allclose(true_move, move, atol=0.1)  # with no force the stylus rests in the hand
        np.testing.assert_allclose(state.position_mm - centre.position_mm, true_move, atol=0.5)
    hand.target = (0.0, 0.0, 0.0)
    session.settle(board.stylus, hand)
    check_forces(session, board, FORCES)
    assert board.refused == 0, "the firmware refused a command in a normal session"


def test_a_press_is_pushed_back_out(rig):
    dev, board, hand = rig
    dev.open()
    session = Session(dev)
    hand.target = (0.0, 0.0, 0.0)
    session.settle(board.stylus, hand)
    hand.target = (20.0, 0.0, 0.0)  # the hand pushes through a wall at x = 10 mm (1 N/mm)

    def wall(state):
        return (-1.0 * max(state.position_mm[0] - 10.0, 0.0), 0.0, 0.0) if state is not None else (0.0, 0.0, 0.0)
    states = session.run(1.5, wall)
    k = board.stylus.hand_k
    expected = (k * 20.0 + 1.0 * 10.0) / (k + 1.0)  # where the hand's spring and the wall balance
    assert np.mean([s.position_mm[0] for s in states[-100:]]) == pytest.approx(expected, abs=0.3)
    assert board.refused == 0


def test_opening_resends_until_the_board_answers(rig):
    dev, board, _hand = rig
    board.stall(0.35)  # still booting: the firmware reads nothing for 350 ms
    t0 = time.monotonic()
    dev.open()
    assert time.monotonic() - t0 >= 0.3
    refused_at_open = board.refused  # copies that piled up while it booted may have merged
    session = Session(dev)
    session.run(0.3)
    assert board.refused == refused_at_open, "the session must start in step"
    assert dev.info.details["model_code"] == 3


def test_a_board_that_never_answers_is_one_line_and_no_hang(rig):
    dev, board, _hand = rig
    board.go_silent()
    dev.handshake_timeout_s = 0.5
    t0 = time.monotonic()
    with pytest.raises(DeviceOpenError, match="never answered the woodenhaptics handshake within 0.5 s") as err:
        dev.open()
    assert time.monotonic() - t0 < 2.0
    assert "\n" not in str(err.value)


class OtherLineBoard(PtySerialDevice):
    """A board that speaks another line protocol."""

    def loop(self) -> None:
        if self.wait_byte() == ord("\n"):
            self.write(b"ERR unknown command\r\n")


def test_a_board_of_another_protocol_is_one_line(tmp_path):
    board = OtherLineBoard(tmp_path, "ttyOTHER0")
    try:
        with pytest.raises(DeviceOpenError, match="not in the WoodenHaptics line format.*ERR unknown") as err:
            WoodenHapticsDevice(board.path).open()
        assert "\n" not in str(err.value)
    finally:
        board.stop()


@pytest.mark.parametrize("rig", [{"reported_model": 7}], indirect=True)
def test_an_unknown_model_code_is_refused_by_name(rig):
    dev, _board, _hand = rig
    with pytest.raises(DeviceOpenError, match=r"reports model code 7.*known: 1 Polhem, 2 vintage PHANTOM.*3 Wooden"):
        dev.open()


def test_a_stall_of_the_board_is_survived_without_merged_commands_or_stale_reads(rig):
    dev, board, hand = rig
    dev.open()
    session = Session(dev)
    hand.target = (0.0, 0.0, 0.0)
    session.settle(board.stylus, hand)
    board.stall(0.2)
    hand.target = (15.0, 0.0, 0.0)  # the hand moves on while the board is stalled
    t0 = time.monotonic()
    session.run(0.2)
    assert session.faults > 0  # reads fail while it is stalled (the daemon writes zero force)
    last_t = 0
    for _ in range(300):
        state = session.tick()
        if state is None or state.t_ns == last_t:  # nothing yet, or the last pose again (a little late)
            continue
        last_t = state.t_ns
        assert dev.counts == tuple(board.counters), "a reply older than the board's newest was used"
        np.testing.assert_allclose(state.position_mm, board.stylus.now(), atol=0.5)
    assert time.monotonic() - t0 < 5.0
    assert board.refused == 0, "two commands merged"


def test_a_stalled_host_gets_a_fresh_reply_not_the_waiting_one(rig):
    dev, board, hand = rig
    dev.open()
    session = Session(dev)
    hand.target = (0.0, 0.0, 0.0)
    session.settle(board.stylus, hand)
    dev.write_force((0.0, 0.0, 0.0))  # its reply arrives and waits while the host is away
    hand.target = (0.0, 15.0, 0.0)
    time.sleep(0.2)
    assert board.watchdog_trips >= 1  # the firmware switched its amplifiers off meanwhile
    state = session.until(lambda s: True)
    np.testing.assert_allclose(state.position_mm, board.stylus.now(), atol=0.5)
    assert dev.stale_replies >= 1
    check_forces(session, board, FORCES[:1])  # the next command switched them on again
    assert board.refused == 0


def test_a_board_that_stops_mid_session_faults_at_once_and_its_watchdog_zeroes_force(rig):
    dev, board, _hand = rig
    dev.open()
    session = Session(dev)
    check_forces(session, board, FORCES[:1])
    board.go_silent()
    session.run(0.01)  # a reply already on its way may still come
    for _ in range(200):
        t0 = time.monotonic()
        with pytest.raises(DeviceFault, match="no reply from the woodenhaptics arm"):
            dev.read()
        assert time.monotonic() - t0 < 0.05  # each read returns at once
        dev.write_force(FORCES[0])
        time.sleep(0.001)
    assert np.allclose(board.motor_force(), 0.0)  # the 100 ms watchdog cut the amplifiers


def test_garbage_on_the_line_is_dropped_and_the_session_resynchronises(rig):
    dev, board, hand = rig
    dev.open()
    session = Session(dev)
    session.run(0.05)
    for junk in [b"junk\n", b"[3,1,2]\n", b"\xff\xfe\n", b"[2,0,0,0,0,0,0,0]\n", b"x" * 300]:
        board.inject(junk)
        session.run(0.05)
    assert dev.rejected_frames >= 4
    state = session.until(lambda s: True)
    np.testing.assert_allclose(state.position_mm, board.stylus.now(), atol=0.5)
    assert board.refused == 0


@pytest.mark.parametrize("rig", [{"gimbal_error_bits": 2}], indirect=True)
def test_gimbal_sensor_errors_are_named_but_do_not_stop_the_session(rig):
    dev, board, _hand = rig
    dev.open()
    session = Session(dev)
    assert len(session.run(0.1)) > 10
    assert dev.info.details["device_errors"] == "gimbal sensor 1 unread"
    assert dev.refused_commands == 0


def test_pulling_the_cable_faults_at_once_and_reconnects(rig):
    dev, board, _hand = rig
    dev.open()
    session = Session(dev)
    session.run(0.05)
    board.unplug()
    t0 = time.monotonic()
    with pytest.raises(DeviceFault, match="lost"):
        for _ in range(3):  # a reply that came before the cable went may still be read
            dev.write_force((0.0, 1.0, 0.0))
            dev.read()
    assert time.monotonic() - t0 < 0.1
    with pytest.raises(DeviceFault, match="still unavailable"):
        dev.reconnect()
    board.replug()
    dev.reconnect()
    state = session.until(lambda s: True)
    np.testing.assert_allclose(state.position_mm, board.stylus.now(), atol=0.5)  # it restarted where it was


def test_closing_leaves_the_motors_at_zero(rig):
    dev, board, _hand = rig
    dev.open()
    session = Session(dev)
    check_forces(session, board, FORCES[:1])
    dev.close()
    assert board.last_command_ma == [0, 0, 0] and dev.last_force_n.tolist() == [0.0, 0.0, 0.0]
    assert np.linalg.norm(board.motor_force()) < 0.01  # 0 mA is half a PWM step off centre
