"""Haply 2DIY driver against the emulated M0/M3 board firmware and pantograph behind a real
pty: what only this board does (the suite every serial arm passes is
test_devices_serial_arms.py; known answers: test_devices_haply_known.py)."""

from __future__ import annotations

import pytest
from sasprobe.devices.base import DeviceOpenError
from sasprobe.devices.haply.driver import create

from tests.emulators import haply_serial
from tests.support.serial_arm_session import Session


@pytest.fixture
def rig(request):
    options = getattr(request, "param", {})
    rig = haply_serial.launch(**options)
    dev = create(rig.device_spec.partition(":")[2])
    yield dev, rig.board, rig.hand
    dev.close()
    rig.close()


def test_the_board_gets_haplys_setup_and_answers_no_setup_message(rig):
    dev, board, _hand = rig
    dev.open()
    assert sorted(board.encoders) == [1, 2] and board.owner == {1: 5, 2: 5}
    assert board.writes >= 1 and board.replies_sent == board.writes  # only writes are answered


@pytest.mark.parametrize("rig", [{"firmware": "v0.1"}], indirect=True)
def test_a_board_on_the_old_header_format_is_one_line(rig):
    dev, _board, _hand = rig
    with pytest.raises(
        DeviceOpenError, match="answered the reset/setup messages.*old v0.1 header format"
    ) as err:
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
