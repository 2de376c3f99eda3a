"""Haply 2DIY driver: known answers from Haply's own library, and closed loops against the
emulated M0/M3 board firmware and pantograph behind a real pty."""

from __future__ import annotations

import math
import struct
import time

import numpy as np
import pytest

from sasprobe.devices.base import DeviceFault, DeviceOpenError
from sasprobe.devices.haply import create, kinematics, protocol
from sasprobe.devices.haply.models import GENERATIONS
from tests.emulators import haply_serial
from tests.serial_arm_session import Session, cosine

# --- known answers -----------------------------------------------------------------------
# HaplyHAPI 1.0.1 (PyPI) HaplyHAPI.py: Pantograph(version) l = 0.07, L = 0.09, d = 0.038
# (version 3) or 0 (2); the README example's add_actuator / add_encoder per version.
HAPLY = {"gen2": dict(l=0.07, L=0.09, d=0.0, centre=(0.0, 0.080)),
         "gen3": dict(l=0.07, L=0.09, d=0.038, centre=(0.019, 0.090))}  # centres: our assumption
ANGLES = {"gen2": [(241.0, -61.0), (200.0, -20.0), (225.0, -30.0), (190.0, -50.0)],
          "gen3": [(168.0, 12.0), (140.0, 40.0), (150.0, 20.0), (120.0, 35.0)]}  # (θ1, θ2) degrees


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
    hh = hx ** 2 + hy ** 2
    hm = math.sqrt(hh)
    cB = -(L2 ** 2 - L1 ** 2 - hh) / (2 * L1 * hm)
    h1x, h1y = L1 * cB * hx / hm, L1 * cB * hy / hm
    h1m = math.sqrt(h1x ** 2 + h1y ** 2)
    sB = math.sqrt(1 - cB ** 2)
    lx, ly = -L1 * sB * h1y / h1m, L1 * sB * h1x / h1m
    x_P, y_P = xA + h1x + lx, yA + h1y + ly
    phi1 = math.acos((x_P - l1 * c1) / L1)
    phi2 = math.acos((x_P - d - l2 * c2) / L2)
    c11, s11, c22, s22 = math.cos(phi1), math.sin(phi1), math.cos(phi2), math.sin(phi2)
    dn = L1 * (c11 * s22 - c22 * s11)
    eta = (-L1 * c11 * s22 + L1 * c22 * s11 - c1 * l1 * s22 + c22 * l1 * s1) / dn
    nu = l2 * (c2 * s22 - c22 * s2) / dn
    J = (-L1 * eta * s11 - L1 * s11 - l1 * s1, L1 * c11 * eta + L1 * c11 + c1 * l1, -L1 * s11 * nu, L1 * c11 * nu)
    return (x_P, y_P), J


@pytest.mark.parametrize("gen", ["gen2", "gen3"])
def test_handle_positions_match_haplys_solution(gen):
    for deg1, deg2 in ANGLES[gen]:
        (x, y), _ = haply_forward(gen, deg1, deg2)
        cx, cy = HAPLY[gen]["centre"]
        expected = [-(x - cx) * 1000, 0.0, (y - cy) * 1000]  # X right = −pad x, Z toward the user = pad y
        got = kinematics.to_device_mm(GENERATIONS[gen], kinematics.handle(GENERATIONS[gen], np.radians([deg1, deg2])))
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
    assert gen3 == bytes([1, 5, 3, 1, 1, 3, 1, 1, 0, 0]) + struct.pack("<4f", 12.0, 4880.0, 168.0, 4880.0)
    gen2 = protocol.encode_setup(5, GENERATIONS["gen2"].ports)
    assert gen2 == bytes([1, 5, 3, 0, 1, 3, 0, 1, 0, 0]) + struct.pack("<4f", -61.0, 10752.0, 241.0, 10752.0)
    assert protocol.encode_write(5, [0.25, -0.5]) == bytes([2, 5]) + struct.pack("<2f", 0.25, -0.5)
    assert protocol.encode_reset() == bytes([0, 0])


def test_torques_go_to_the_ports_haply_assigns_and_are_clamped_together():
    dev = create("gen3:/dev/null")
    dev.theta = np.radians([150.0, 20.0])
    _, (J11, J12, J21, J22) = haply_forward("gen3", 150.0, 20.0)
    tau1, tau2 = J11 * -0.4, J21 * -0.4  # a force of 0.4 N along X: pad fx = −0.4
    np.testing.assert_allclose(dev.port_torques([0.4, 0.0, 0.0]), [tau2, tau1], atol=1e-12)  # port 1 drives link 2
    big = dev.port_torques([30.0, 0.0, -20.0])
    assert max(abs(t) for t in big) == pytest.approx(protocol.MAX_TORQUE_NM)  # the board clamps each at 0.123 N·m
    small = dev.port_torques([0.3, 0.0, -0.2])
    np.testing.assert_allclose(np.array(big) / np.linalg.norm(big), np.array(small) / np.linalg.norm(small),
                               atol=1e-12)


def test_the_declared_force_is_renderable_everywhere_in_the_box():
    for gen in GENERATIONS.values():
        half = gen.limits.workspace_max_mm[0] / 1000.0
        cx, cy = gen.workspace_centre_m
        for x in np.linspace(cx - half, cx + half, 9):
            for y in np.linspace(cy - half, cy + half, 9):
                theta = _inverse(gen, x, y)
                jac = kinematics.jacobian(gen, theta)
                # the largest force the 0.123 N·m clamp allows in every direction
                assert protocol.MAX_TORQUE_NM / max(np.linalg.norm(jac[:, 0]), np.linalg.norm(jac[:, 1])) \
                    >= gen.limits.max_force_n


def _inverse(gen, x, y):
    theta = np.radians([gen.port_for(1).start_angle_deg, gen.port_for(2).start_angle_deg])
    for _ in range(50):
        err = np.array([x, y]) - kinematics.handle(gen, theta)
        theta = theta + np.linalg.solve(kinematics.jacobian(gen, theta), err)
    return theta


@pytest.mark.parametrize("frame", [bytes([6]) + struct.pack("<2f", 1.0, 2.0), bytes([5]) + struct.pack("<f", 1.0),
                                   bytes([5]) + struct.pack("<2f", float("nan"), 2.0)])
def test_foreign_short_and_non_finite_frames_are_rejected(frame):
    with pytest.raises(protocol.BadFrame):
        protocol.decode_angles(frame, 5, 2)


def test_the_device_string_names_the_generation():
    assert create("/dev/ttyACM0").generation is GENERATIONS["gen3"]
    assert create("gen2:/dev/ttyACM0").generation is GENERATIONS["gen2"]
    assert create("gen2:/dev/ttyACM0").port == "/dev/ttyACM0"


# --- against the emulated board ---------------------------------------------------------------

@pytest.fixture
def rig(request):
    options = getattr(request, "param", {})
    rig = haply_serial.launch(**options)
    dev = create(rig.device_spec.partition(":")[2])
    yield dev, rig.board, rig.hand
    dev.close()
    rig.close()


MOVES = [(10, 0, 0), (-10, 0, 0), (0, 0, 10), (0, 0, -10), (7, 0, -7)]
FORCES = [(0.8, 0.0, 0.0), (0.0, 0.0, -0.8), (0.5, 0.0, 0.6)]


def check_forces(session, board, forces) -> None:
    for force in forces:
        session.hold(force, board)
        made = board.motor_force()
        in_plane = np.array([force[0], 0.0, force[2]])
        assert cosine(made, in_plane) >= 0.99, (force, made)
        assert np.linalg.norm(made) == pytest.approx(np.linalg.norm(in_plane), rel=0.05), (force, made)


@pytest.mark.parametrize("rig", [{"generation": "gen3", "board": "M0"}, {"generation": "gen3", "board": "M3"},
                                 {"generation": "gen2", "board": "M0"}], indirect=True,
                         ids=["gen3-M0", "gen3-M3", "gen2-M0"])
def test_displacements_and_forces_in_the_device_frame(rig):
    dev, board, hand = rig
    dev.open()
    session = Session(dev)
    session.reads_the_stylus(board.stylus)  # the start pose the setup declared
    hand.target = (0.0, 0.0, 0.0)
    centre = session.settle(board.stylus, hand)
    centre_true = board.stylus.now()
    np.testing.assert_allclose(centre.position_mm, centre_true, atol=0.5)
    for move in MOVES:
        hand.target = move
        state = session.settle(board.stylus, hand)
        true_move = board.stylus.now() - centre_true
        np.testing.assert_allclose(true_move, move, atol=0.1)
        np.testing.assert_allclose(state.position_mm - centre.position_mm, true_move, atol=0.5)
        assert state.position_mm[1] == 0.0  # planar
    hand.target = (0.0, 0.0, 0.0)
    session.settle(board.stylus, hand)
    check_forces(session, board, FORCES + [(0.3, 2.0, -0.4)])  # the Y part is dropped
    assert dev.rejected_frames == 0 and dev.resyncs == 0  # every reply in step with its write


def test_the_board_gets_haplys_setup_and_answers_no_setup_message(rig):
    dev, board, _hand = rig
    dev.open()
    assert sorted(board.encoders) == [1, 2] and board.owner == {1: 5, 2: 5}
    assert board.writes >= 1 and board.replies_sent == board.writes  # only writes are answered


def test_opening_resends_until_the_board_answers(rig):
    dev, board, _hand = rig
    board.stall(0.35)
    t0 = time.monotonic()
    dev.open()
    assert time.monotonic() - t0 >= 0.3
    session = Session(dev)
    session.reads_the_stylus(board.stylus)


def test_a_board_that_never_answers_is_one_line_and_no_hang(rig):
    dev, board, _hand = rig
    board.go_silent()
    dev.handshake_timeout_s = 0.5
    t0 = time.monotonic()
    with pytest.raises(DeviceOpenError, match="never answered within 0.5 s") as err:
        dev.open()
    assert time.monotonic() - t0 < 2.0 and "\n" not in str(err.value)


@pytest.mark.parametrize("rig", [{"firmware": "v0.1"}], indirect=True)
def test_a_board_on_the_old_header_format_is_one_line(rig):
    dev, _board, _hand = rig
    with pytest.raises(DeviceOpenError, match="answered the reset/setup messages.*old v0.1 header format") as err:
        dev.open()
    assert "\n" not in str(err.value)


class ForgetfulBoard(haply_serial.HaplyBoard):
    """Loses its first setup message (its bytes are eaten): answers writes with its ID alone."""

    lost = False

    def _setup(self) -> None:
        if not self.lost:
            self.lost = True
            self.read_bytes(64, 0.005)
            return
        super()._setup()


def test_a_board_that_missed_the_setup_is_set_up_again(tmp_path):
    board = ForgetfulBoard(tmp_path)
    dev = create(str(board.path))
    try:
        dev.open()
        assert dev.setups_sent == 2 and board.owner == {1: 5, 2: 5}
        Session(dev).reads_the_stylus(board.stylus)
    finally:
        dev.close()
        board.stop()


def test_a_stall_of_the_board_is_survived_without_stale_reads(rig):
    dev, board, hand = rig
    dev.open()
    session = Session(dev)
    hand.target = (0.0, 0.0, 0.0)
    session.settle(board.stylus, hand)
    board.stall(0.2)
    hand.target = (15.0, 0.0, 0.0)
    session.run(0.2)
    assert session.faults > 0
    for _ in range(300):
        state = session.tick()
        if state is None:
            continue
        np.testing.assert_allclose(state.position_mm, board.stylus.now(), atol=0.5)
    assert dev.resyncs == 0 and dev.rejected_frames == 0  # no second copy went out: no second answer came


def test_a_stalled_host_gets_a_fresh_reply_not_the_waiting_one(rig):
    dev, board, hand = rig
    dev.open()
    session = Session(dev)
    hand.target = (0.0, 0.0, 0.0)
    session.settle(board.stylus, hand)
    dev.write_force((0.0, 0.0, 0.0))
    hand.target = (0.0, 0.0, 15.0)
    time.sleep(0.2)
    session.reads_the_stylus(board.stylus)
    assert dev.stale_replies >= 1


def test_a_board_that_stops_mid_session_is_one_line_and_gets_zero_when_back(rig):
    dev, board, _hand = rig
    dev.open()
    session = Session(dev)
    check_forces(session, board, FORCES[:1])
    board.go_silent()
    session.run(0.01)
    for _ in range(100):
        t0 = time.monotonic()
        with pytest.raises(DeviceFault, match="no reply from the haply arm"):
            dev.read()
        assert time.monotonic() - t0 < 0.05
        dev.write_force((0.0, 0.0, 0.0))  # what the daemon writes on a fault
        time.sleep(0.001)
    board.resume()
    session.reads_the_stylus(board.stylus)
    assert np.allclose(board.motor_force(), 0.0)  # the board has no watchdog: zero had to be written


def test_garbage_on_the_line_is_dropped_and_the_session_resynchronises(rig):
    dev, board, _hand = rig
    dev.open()
    session = Session(dev)
    session.run(0.05)
    for junk in [b"\xff\xfe\xfd", bytes([9]) + struct.pack("<2f", 1.0, 2.0), bytes([5]) * 3]:
        board.inject(junk)
        session.run(0.05)
    assert dev.rejected_frames >= 2
    session.reads_the_stylus(board.stylus)


def test_pulling_the_cable_faults_at_once_and_reconnects(rig):
    dev, board, _hand = rig
    dev.open()
    session = Session(dev)
    session.run(0.05)
    board.unplug()
    with pytest.raises(DeviceFault, match="lost"):
        for _ in range(3):
            dev.write_force((0.5, 0.0, 0.0))
            dev.read()
    with pytest.raises(DeviceFault, match="still unavailable"):
        dev.reconnect()
    board.replug()  # a replugged board restarted: it needs the setup again (handle in the start pose)
    dev.reconnect()
    assert dev.setups_sent == 2
    session.reads_the_stylus(board.stylus)


def test_closing_leaves_the_motors_at_zero(rig):
    dev, board, _hand = rig
    dev.open()
    session = Session(dev)
    check_forces(session, board, FORCES[:1])
    dev.close()
    time.sleep(0.05)
    assert np.allclose(board.motor_force(), 0.0) and dev.last_force_n.tolist() == [0.0, 0.0, 0.0]
