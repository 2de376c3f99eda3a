"""Haply 2DIY driver against the emulated hAPI board behind a real pty."""

from __future__ import annotations

import struct

import numpy as np
import pytest

from sasprobe.devices import haply as H
from tests import device_loop as loop
from tests.emulators.haply_serial import Haply2DIYEmulator, start_pose_mm
from tests.emulators.physics import MovableHand


def test_messages_follow_the_public_layout():
    msg = H.encode_message(H.TYPE_TORQUES, H.port_mask([1, 2]), 5, [0.5, -0.25])
    assert msg == bytes([0x13, 5]) + struct.pack("<2f", 0.5, -0.25)
    setup = H.encode_message(H.TYPE_SETUP, H.port_mask([1, 2]), 5, [180.0, 13824.0, 0.0, 13824.0])
    assert setup[0] == 0x03 and len(setup) == 2 + 16
    assert H.port_mask([1, 3, 4]) == 0b1101
    with pytest.raises(ValueError):
        H.port_mask([5])


@pytest.mark.parametrize("reply", [
    bytes([6]) + struct.pack("<2f", 1.0, 2.0),  # another device's ID
    bytes([5]) + struct.pack("<f", 1.0),  # short
    bytes([5]) + struct.pack("<3f", 1.0, 2.0, 3.0),  # long
    bytes([5]) + struct.pack("<2f", float("nan"), 2.0),  # not a number
    bytes([5]) + struct.pack("<2f", 1e9, 2.0),  # not an angle
])
def test_malformed_replies_are_rejected(reply):
    assert H.decode_angles(reply, 5, 2) is None


def pantograph_frame(state) -> np.ndarray:
    """A reported position in the emulator's (pantograph) frame."""
    return state.position_mm + np.append(H.WORKSPACE_CENTRE_XY_MM, 0.0)


@pytest.fixture
def rig(tmp_path):
    hand = MovableHand(start_pose_mm())
    emu = Haply2DIYEmulator(tmp_path, hand=hand)
    dev = H.Haply2DIYDevice(emu.path)
    yield dev, emu, hand
    dev.close()
    emu.stop()


def test_setup_then_positions_and_forces_round_trip(rig):
    dev, emu, hand = rig
    dev.open()
    assert emu.offsets_deg.tolist() == [180.0, 0.0] and emu.resolution.tolist() == [13824.0, 13824.0]
    state = dev.read()
    assert state.calibrated and dev.info.limits.has_force_output
    for target in [(0.0, -80.0, 0.0), (30.0, -70.0, 0.0), (-25.0, -95.0, 0.0)]:
        hand.target = target
        loop.run(dev, 0.5)
        state = dev.read()
        assert state.position_mm[2] == 0.0
        np.testing.assert_allclose(pantograph_frame(state), emu.stylus.position, atol=0.05)  # 13824 counts/turn
        for force in ([0.8, -0.5, 0.0], [-1.0, 1.2, 0.7]):
            dev.write_force(force)
            dev.read()
            np.testing.assert_allclose(emu.last_force_n, [force[0], force[1], 0.0], atol=1e-3)


def test_forces_never_exceed_the_declared_limit(rig):
    dev, emu, hand = rig
    dev.open()
    hand.target = (0.0, -75.0, 0.0)
    loop.run(dev, 0.3)
    rng = np.random.default_rng(11)
    for command in [rng.normal(size=3) * 30 for _ in range(150)] + [[np.nan, 1, 0], [1e308, 1e308, 0]]:
        dev.write_force(command)
        dev.read()
        assert np.all(np.abs(emu.torques) <= H.TORQUE_LIMIT_NM + 1e-6)
        assert np.linalg.norm(emu.last_force_n) <= H.HAPLY_2DIY_LIMITS.max_force_n + 1e-3
    assert emu.max_force_n <= H.HAPLY_2DIY_LIMITS.max_force_n + 1e-3


def test_closed_loop_virtual_wall(rig):
    dev, emu, hand = rig
    dev.open()
    hand.target = (20.0, -75.0, 0.0)
    states = loop.run(dev, 2.0, force_of=loop.wall(axis=0, at_mm=10.0, stiffness_n_per_mm=0.5))
    k = emu.stylus.hand_k
    expected = (k * 20.0 + 0.5 * 10.0) / (k + 0.5)
    assert np.mean([s.position_mm[0] for s in states[-100:]]) == pytest.approx(expected, abs=0.3)


def test_malformed_replies_are_counted_and_skipped(rig):
    dev, emu, _hand = rig
    dev.open()
    dev.read()
    cases = [("junk", [b"\xff\xfe\xfd"], None), ("short", [], bytes([5]) + b"\x00\x00"),
             ("long", [], bytes([5]) + b"\x00" * 12), ("foreign id", [], bytes([9]) + struct.pack("<2f", 180.0, 0.0)),
             ("nan", [], bytes([5]) + struct.pack("<2f", float("nan"), 0.0))]
    for _name, junk, override in cases:
        emu.inject_before_reply = junk
        emu.reply_override = override
        dev.write_force([0, 0, 0])
        state = dev.read()
        np.testing.assert_allclose(pantograph_frame(state), emu.stylus.position, atol=0.05)
    assert dev.rejected_frames == len(cases)


def test_pulling_the_cable_faults_at_once_and_recovers(rig):
    dev, emu, _hand = rig
    dev.open()
    dev.read()
    assert loop.pull_the_cable(dev, emu.unplug, emu.replug, command=[0.5, 0.0, 0.0]).calibrated


def test_a_board_that_never_answers_is_an_open_error(tmp_path):
    emu = Haply2DIYEmulator(tmp_path, device_id=7)  # answers only ID 7: our setup goes unanswered
    try:
        with pytest.raises(Exception, match="did not answer like a haply arm"):
            H.Haply2DIYDevice(emu.path).open()
    finally:
        emu.stop()
