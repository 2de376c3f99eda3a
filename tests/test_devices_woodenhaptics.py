"""WoodenHaptics/Polhem driver in closed loop against the emulated Teensy firmware and
mechanism behind a real pty (known answers: test_devices_woodenhaptics_known.py)."""

from __future__ import annotations

import time

import numpy as np
import pytest

from sasprobe.devices.base import DeviceFault, DeviceOpenError
from sasprobe.devices.woodenhaptics import WoodenHapticsDevice
from tests.emulators import woodenhaptics_serial
from tests.emulators.pty_serial import PtySerialDevice
from tests.serial_arm_session import Session, cosine


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
        session.hold(force, board)
        made = board.motor_force()
        assert cosine(made, force) >= 0.99, (force, made)
        assert np.linalg.norm(made) == pytest.approx(np.linalg.norm(force), rel=0.05), (force, made)


@pytest.mark.parametrize("rig", [{"model": 1}, {"model": 2}, {"model": 3}], indirect=True,
                         ids=["polhem", "vintage", "woody"])
def test_displacements_and_forces_in_the_device_frame(rig):
    dev, board, hand = rig
    dev.open()
    session = Session(dev)
    session.reads_the_stylus(board.stylus)  # the home pose, where counts are 0
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
    session.reads_the_stylus(board.stylus)
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
    session.reads_the_stylus(board.stylus)
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
    session.reads_the_stylus(board.stylus)  # it restarted where it was


def test_closing_leaves_the_motors_at_zero(rig):
    dev, board, _hand = rig
    dev.open()
    session = Session(dev)
    check_forces(session, board, FORCES[:1])
    dev.close()
    assert board.last_command_ma == [0, 0, 0] and dev.last_force_n.tolist() == [0.0, 0.0, 0.0]
    assert np.linalg.norm(board.motor_force()) < 0.01  # 0 mA is half a PWM step off centre
