"""WoodenHaptics/Polhem driver against the emulated Teensy firmware and mechanism behind a
real pty: what only these boards do (the suite every serial arm passes is
test_devices_serial_arms.py; known answers: test_devices_woodenhaptics_known.py)."""

from __future__ import annotations

import pytest
from sasprobe.devices.base import DeviceOpenError
from sasprobe.devices.woodenhaptics.driver import WoodenHapticsDevice

from tests.emulators import woodenhaptics_serial
from tests.emulators.pty_serial import PtySerialDevice
from tests.support.serial_arm_session import Session, assert_no_refusals_but_after_deafness


@pytest.fixture
def rig(request):
    options = getattr(request, "param", {})
    rig = woodenhaptics_serial.launch(**options)
    dev = WoodenHapticsDevice(rig.board.path)
    yield dev, rig.board, rig.hand
    dev.close()
    rig.close()


def test_a_press_is_pushed_back_out(rig):
    dev, board, hand = rig
    dev.open()
    session = Session(dev)
    hand.target = (0.0, 0.0, 0.0)
    session.settle(board.stylus, hand)
    hand.target = (20.0, 0.0, 0.0)  # the hand pushes through a wall at x = 10 mm (1 N/mm)

    def wall(state):
        return (
            (-1.0 * max(state.position_mm[0] - 10.0, 0.0), 0.0, 0.0)
            if state is not None
            else (0.0, 0.0, 0.0)
        )

    # the stylus comes to rest where the hand's spring and the wall balance (a loop that runs
    # late on a busy machine renders the wall late, and the stylus swings until it catches up)
    state = session.settle(board.stylus, hand, timeout_s=30.0, force=wall)
    k = board.stylus.hand_k
    expected = (k * 20.0 + 1.0 * 10.0) / (k + 1.0)
    assert board.stylus.now()[0] == pytest.approx(expected, abs=0.3)
    assert state.position_mm[0] == pytest.approx(expected, abs=0.3)
    assert_no_refusals_but_after_deafness(board)


class OtherLineBoard(PtySerialDevice):
    """A board that speaks another line protocol."""

    def loop(self) -> None:
        if self.wait_byte() == ord("\n"):
            self.write(b"ERR unknown command\r\n")


def test_a_board_of_another_protocol_is_one_line(tmp_path):
    board = OtherLineBoard(tmp_path, "ttyOTHER0")
    try:
        with pytest.raises(
            DeviceOpenError, match="not in the WoodenHaptics line format.*ERR unknown"
        ) as err:
            WoodenHapticsDevice(board.path).open()
        assert "\n" not in str(err.value)
    finally:
        board.stop()


@pytest.mark.parametrize("rig", [{"reported_model": 7}], indirect=True)
def test_an_unknown_model_code_is_refused_by_name(rig):
    dev, _board, _hand = rig
    with pytest.raises(
        DeviceOpenError, match=r"reports model code 7.*known: 1 Polhem, 2 vintage PHANTOM.*3 Wooden"
    ):
        dev.open()


@pytest.mark.parametrize("rig", [{"gimbal_error_bits": 2}], indirect=True)
def test_gimbal_sensor_errors_are_named_but_do_not_stop_the_session(rig):
    dev, board, _hand = rig
    dev.open()
    session = Session(dev)
    assert len(session.run(0.1)) > 10
    assert dev.info.details["device_errors"] == "gimbal sensor 1 unread"
    assert dev.refused_commands == 0
