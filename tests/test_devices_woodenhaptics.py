"""WoodenHaptics driver against the emulated Teensy firmware behind a real pty."""

from __future__ import annotations

import time

import numpy as np
import pytest

from sasprobe.devices import woodenhaptics as W
from sasprobe.devices.base import DeviceOpenError
from tests import device_loop as loop
from tests.emulators.physics import MovableHand
from tests.emulators.woodenhaptics_serial import WoodenHapticsEmulator


def test_command_and_reply_lines_follow_the_public_format():
    assert W.encode_command([12.4, -300.0, 0.0]) == b"[12,-300,0]\n"
    assert W.parse_reply(b"[3,10,-20,30,1,2,3,0]") == (3, [10, -20, 30, 1, 2, 3], 0)
    assert W.parse_reply(b"[2,0,0,0,0,0,0,1536]\r") == (2, [0] * 6, 1536)


@pytest.mark.parametrize("line", [b"3,0,0,0,0,0,0,0]", b"[3,0,0,0,0,0,0,0", b"[3,0,0,0]", b"[3,0,0,0,0,0,0,0,0]",
                                  b"[3,x,0,0,0,0,0,0]", b"[3,0.5,0,0,0,0,0,0]", b"\xff\xfe", b""])
def test_malformed_reply_lines_are_rejected(line):
    with pytest.raises(W.LineError):
        W.parse_reply(line)


def test_error_bits_are_named():
    assert W.describe_errors(512 | 2) == "gimbal 1 I2C, wrong field count"
    assert W.describe_errors(0) == "none"


@pytest.fixture
def rig(tmp_path):
    hand = MovableHand()
    emu = WoodenHapticsEmulator(tmp_path, hand=hand)
    hand.target = tuple(emu.stylus.position)  # resting in the home pose, where the button was pressed
    dev = W.WoodenHapticsDevice(emu.path)
    yield dev, emu, hand
    dev.close()
    emu.stop()


def centre_of(emu):
    return emu.arm.forward(emu.arm.geometry.centre_joint_angles)


def test_calibration_needs_the_home_pose_and_gates_force(rig):
    dev, emu, hand = rig
    dev.open()
    assert dev.info.model == "WoodenHaptics Woody" and dev.info.limits == W.WOODEN_MODELS[3].limits
    state = dev.read()
    assert not state.calibrated
    dev.write_force([0.0, 2.0, 0.0])
    dev.read()
    assert emu.currents.tolist() == [0, 0, 0]  # refused while uncalibrated
    state = loop.until(dev, lambda s: s.calibrated)
    dev.write_force([0.0, 2.0, 0.0])
    dev.read()  # the reply means the emulator has taken the command
    assert np.any(emu.currents != 0)


def test_an_arm_away_from_home_stays_uncalibrated_until_it_returns(rig):
    dev, emu, hand = rig
    hand.target = tuple(centre_of(emu))
    time.sleep(0.05)
    dev.open()
    states = loop.run(dev, 0.3)
    assert not any(s.calibrated for s in states)
    hand.target = tuple(emu.arm.forward(emu.model.home_joint_angles))
    loop.until(dev, lambda s: s.calibrated)


def test_positions_and_forces_round_trip(rig):
    dev, emu, hand = rig
    dev.open()
    loop.until(dev, lambda s: s.calibrated)
    for offset in [(0.0, 0.0, 0.0), (40.0, -20.0, 10.0), (-50.0, 30.0, -25.0)]:
        hand.target = tuple(np.asarray(offset) + 0.0)  # the device frame's origin is the workspace centre
        loop.run(dev, 0.6)
        state = dev.read()
        np.testing.assert_allclose(state.position_mm, emu.stylus.position, atol=0.1)  # ≈0.04 mm per count
        for force in ([1.0, 2.0, -1.5], [-3.0, 0.5, 2.0]):
            dev.write_force(force)
            dev.read()
            np.testing.assert_allclose(emu.last_force_n, force, atol=0.02)  # currents are whole mA
    assert emu.bad_lines == 0  # every command the driver sent was well-formed


def test_forces_never_exceed_the_declared_limit(rig):
    dev, emu, hand = rig
    dev.open()
    loop.until(dev, lambda s: s.calibrated)
    hand.target = (0.0, 0.0, 0.0)
    loop.run(dev, 0.5)
    rng = np.random.default_rng(3)
    limit = W.WOODEN_MODELS[3].limits.max_force_n
    for command in [rng.normal(size=3) * 50 for _ in range(150)] + [[np.nan, 0, 0], [-np.inf, 1, 1]]:
        dev.read()
        currents = dev.currents_for(command)
        assert np.all(np.abs(currents) <= W.WOODEN_MODELS[3].max_current_ma)
        dev.write_force(command)
        dev.read()
        assert np.linalg.norm(emu.last_force_n) <= limit + 0.02
    assert emu.max_force_n <= limit + 0.02


def test_closed_loop_virtual_wall(rig):
    dev, emu, hand = rig
    dev.open()
    loop.until(dev, lambda s: s.calibrated)
    hand.target = (20.0, 0.0, 0.0)
    states = loop.run(dev, 2.0, force_of=loop.wall(axis=0, at_mm=10.0, stiffness_n_per_mm=1.0))
    expected = (emu.stylus.hand_k * 20.0 + 1.0 * 10.0) / (emu.stylus.hand_k + 1.0)
    assert np.mean([s.position_mm[0] for s in states[-100:]]) == pytest.approx(expected, abs=0.3)


def test_device_error_bits_are_surfaced(rig):
    dev, emu, _hand = rig
    dev.open()
    emu.gimbal_error_bits = 2 | 512
    dev.read()
    assert dev.device_error_bits == 2 | 512
    assert dev.info.details["device_errors"] == "gimbal 1 I2C, wrong field count"
    assert dev.refused_commands == 1 and dev.gimbal_errors == 1


def test_the_100_ms_watchdog_is_respected(rig):
    dev, emu, _hand = rig
    dev.open()
    loop.until(dev, lambda s: s.calibrated)
    dev.write_force([0.0, 2.0, 0.0])
    dev.read()
    assert emu.amplifiers_on
    time.sleep(0.3)  # the host falls silent
    assert not emu.amplifiers_on and emu.watchdog_trips == 1
    dev.write_force([0.0, 2.0, 0.0])  # first command after the gap: zero, so nothing jumps
    dev.read()
    assert dev.watchdog_gaps == 1 and emu.currents.tolist() == [0, 0, 0]
    dev.write_force([0.0, 2.0, 0.0])
    dev.read()
    assert np.any(emu.currents != 0)


def test_malformed_replies_are_counted_and_skipped(rig):
    dev, emu, _hand = rig
    dev.open()
    dev.read()
    injected = [b"junk\n", b"[3,1,2]\n", b"[3,a,0,0,0,0,0,0]\n", b"3,0,0,0,0,0,0,0]\n", b"\xff\xfe\n",
                b"[2,0,0,0,0,0,0,0]\n", b"x" * 300 + b"\n"]
    for bad in injected:
        emu.inject_before_reply = [bad]
        dev.write_force([0, 0, 0])
        state = dev.read()
        np.testing.assert_allclose(state.position_mm, emu.stylus.position, atol=0.1)
    assert dev.rejected_frames == len(injected)


def test_pulling_the_cable_faults_at_once_and_recovers(rig):
    dev, emu, _hand = rig
    dev.open()
    loop.until(dev, lambda s: s.calibrated)
    # replugged, the Teensy restarts: torque off until its button is pressed again
    state = loop.pull_the_cable(dev, emu.unplug, emu.replug, command=[0.0, 1.0, 0.0])
    assert not state.calibrated
    emu.press_calibration_button()
    loop.until(dev, lambda s: s.calibrated)


@pytest.mark.parametrize("code, message", [(1, "kinematics are not publicly described"), (7, "does not know")])
def test_unknown_and_undescribed_models_are_refused(tmp_path, code, message):
    emu = WoodenHapticsEmulator(tmp_path)
    emu.reported_model = code
    try:
        with pytest.raises(DeviceOpenError, match=message):
            W.WoodenHapticsDevice(emu.path).open()
    finally:
        emu.stop()
