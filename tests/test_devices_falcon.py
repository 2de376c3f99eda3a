"""Novint Falcon driver against the emulated Falcon behind a pyusb backend."""

from __future__ import annotations

import os
import time

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from sasprobe.devices import falcon as F
from sasprobe.devices.base import DeviceFault, DeviceOpenError
from tests import device_loop as loop
from tests.emulators.falcon_usb import EmulatedUsbBackend, FalconHardware
from tests.emulators.physics import MovableHand


# --- wire format ----------------------------------------------------------------------------

@settings(max_examples=300, deadline=None)
@given(st.lists(st.integers(-32768, 32767), min_size=3, max_size=3), st.integers(0, 255))
def test_frame_round_trip(values, flags):
    frame = F.encode_frame(values, flags)
    assert len(frame) == 16 and frame[:1] == b"<" and frame[-1:] == b">"
    assert all(0x41 <= b <= 0x50 for b in frame[1:15])
    assert F.decode_frame(frame) == (values, flags)


def test_frame_layout_follows_the_public_description():
    # 0x1234: nibbles 4, 3, 2, 1 least significant first, each + 0x41; flags 0x2A → 'K', 'C'
    frame = F.encode_frame([0x1234, -1, 0], 0x2A)
    assert frame == b"<" + bytes([0x41 + 4, 0x41 + 3, 0x41 + 2, 0x41 + 1]) + b"PPPP" + b"AAAA" + b"KC" + b">"


@pytest.mark.parametrize("bad", [
    b"<AAAAAAAAAAAAAA",  # 15 bytes
    b"<AAAAAAAAAAAAAAA>",  # 17 bytes
    b"[AAAAAAAAAAAAAA>",  # wrong start
    b"<AAAAAAAAAAAAAA]",  # wrong end
    b"<AAAAAAAQAAAAAA>",  # 'Q' is not a nibble
    b"<AAAAAAA@AAAAAA>",  # '@' is below 'A'
])
def test_malformed_frames_are_rejected(bad):
    with pytest.raises(F.FrameError):
        F.decode_frame(bad)


def test_frame_reader_skips_and_counts_junk_and_bad_frames():
    good = F.encode_frame([1, 2, 3], 0x10)
    reader = F.FrameReader()
    reader.feed(b"\x00junk" + good + b"<AAAAZAAAAAAAAA>" + good + b"<AAA" + good)
    frames = []
    while (frame := reader.next_frame()) is not None:
        frames.append(frame)
    assert frames == [([1, 2, 3], 0x10)] * 3
    assert reader.rejected == 3  # the junk run, the bad nibble frame, the truncated frame


# --- emulated device ------------------------------------------------------------------------

@pytest.fixture
def firmware(tmp_path):
    image = os.urandom(700)  # not a multiple of 128: the last block is short
    path = tmp_path / "falcon_firmware.bin"
    path.write_bytes(image)
    return path, image


@pytest.fixture
def rig(firmware):
    path, image = firmware
    hand = MovableHand()
    hw = FalconHardware(image, hand=hand)
    dev = F.FalconDevice(path, usb_backend=EmulatedUsbBackend(hw))
    yield dev, hw, hand
    dev.close()


def home(dev, hand):
    hand.target = (0.0, 0.0, 35.0)  # every thigh passes its index mark at 35°
    state = loop.until(dev, lambda s: s.calibrated)
    hand.target = (0.0, 0.0, 0.0)
    return state


def test_firmware_upload_then_frames(rig):
    dev, hw, _hand = rig
    assert not hw.running
    dev.open()
    assert hw.running and dev.firmware_uploads == 1 and hw.upload_attempts == 1
    state = dev.read()
    assert state.calibrated is False  # not homed yet
    # a Falcon already running its firmware is not uploaded to again
    dev.close()
    dev.open()
    assert dev.firmware_uploads == 1


def test_a_bad_echo_retries_the_upload(firmware):
    path, image = firmware
    hw = FalconHardware(image, corrupt_echo_attempts={1})
    dev = F.FalconDevice(path, usb_backend=EmulatedUsbBackend(hw))
    dev.open()
    assert dev.upload_retries == 1 and hw.upload_attempts == 2 and hw.running
    dev.close()


def test_the_wrong_firmware_is_reported(firmware, tmp_path):
    _path, image = firmware
    wrong = tmp_path / "other.bin"
    wrong.write_bytes(os.urandom(256))
    dev = F.FalconDevice(wrong, usb_backend=EmulatedUsbBackend(FalconHardware(image)))
    with pytest.raises(DeviceOpenError, match="did not start after the firmware upload"):
        dev.open()


def test_no_firmware_running_and_none_given(firmware):
    _path, image = firmware
    dev = F.FalconDevice(None, usb_backend=EmulatedUsbBackend(FalconHardware(image)))
    with pytest.raises(DeviceOpenError, match="no firmware running"):
        dev.open()


def test_missing_firmware_file_and_missing_device(firmware, tmp_path):
    _path, image = firmware
    with pytest.raises(DeviceOpenError, match="firmware file not found"):
        F.FalconDevice(tmp_path / "nope.bin", usb_backend=EmulatedUsbBackend(FalconHardware(image))).open()
    hw = FalconHardware(image)
    hw.unplug()
    with pytest.raises(DeviceOpenError, match="no Novint Falcon found"):
        F.FalconDevice(_path, usb_backend=EmulatedUsbBackend(hw)).open()


def test_homing_gates_force_and_switches_the_leds(rig):
    dev, hw, hand = rig
    dev.open()
    dev.read()
    dev.write_force([0.0, 3.0, 0.0])
    assert hw.motor == [0, 0, 0]  # refused until homed
    assert hw.flags & F.HOMING_MODE and hw.flags & F.LED_RED
    home(dev, hand)
    dev.read()
    dev.write_force([0.0, 3.0, 0.0])
    assert hw.motor != [0, 0, 0]
    assert hw.flags & F.LED_GREEN and not hw.flags & F.HOMING_MODE


def test_positions_and_forces_round_trip(rig):
    dev, hw, hand = rig
    dev.open()
    home(dev, hand)
    for target in [(20.0, -10.0, 5.0), (-30.0, 25.0, -20.0), (0.0, 0.0, 30.0)]:
        hand.target = target
        loop.run(dev, 0.4)
        state = dev.read()
        # the reply reports the pose of the last frame; encoder steps are ≈0.04 mm here
        np.testing.assert_allclose(state.position_mm, hw.stylus.position, atol=0.1)
        for force in ([1.0, 2.0, -3.0], [-4.0, 0.5, 2.0]):
            dev.write_force(force)
            # within the quantisation of the torques to ±4096 counts
            np.testing.assert_allclose(hw.last_force_n, force, atol=0.01)
            dev.read()


def test_buttons_come_through(rig):
    dev, hw, _hand = rig
    dev.open()
    hw.buttons = 0b0101
    dev.read()
    assert dev.read().buttons == 0b0101


def test_forces_never_exceed_the_declared_limit(rig):
    dev, hw, hand = rig
    dev.open()
    home(dev, hand)
    rng = np.random.default_rng(7)
    commands = [rng.normal(size=3) * 100.0 for _ in range(200)] + [[np.nan, 1.0, 1.0], [np.inf, 0, 0], [1e300] * 3]
    for command in commands:
        dev.read()
        motor = dev.motor_command(command)
        assert max(abs(m) for m in motor) <= F.MOTOR_LIMIT
        dev.write_force(command)
        produced = hw.last_force_n
        assert np.linalg.norm(produced) <= F.FALCON_LIMITS.max_force_n + 0.01
        if np.all(np.isfinite(command)) and np.linalg.norm(produced) > 1.0:  # direction survives scaling
            direction = np.asarray(command) / np.max(np.abs(command))
            cosine = produced @ direction / np.linalg.norm(produced) / np.linalg.norm(direction)
            assert cosine > 0.999
    assert hw.max_command_force_n <= F.FALCON_LIMITS.max_force_n + 0.01
    dev.write_force([np.nan, np.nan, np.nan])
    assert hw.motor == [0, 0, 0]


def test_closed_loop_virtual_wall_settles_where_the_springs_balance(rig):
    dev, hw, hand = rig
    dev.open()
    home(dev, hand)
    hand.target = (20.0, 0.0, 0.0)
    states = loop.run(dev, 2.0, force_of=loop.wall(axis=0, at_mm=10.0, stiffness_n_per_mm=1.0))
    # hand spring 0.5 N/mm pulling to 20 mm against a 1 N/mm wall at 10 mm: x = (0.5·20 + 1·10)/1.5
    expected = (hw.stylus.hand_k * 20.0 + 1.0 * 10.0) / (hw.stylus.hand_k + 1.0)
    settled = np.mean([s.position_mm[0] for s in states[-100:]])
    assert settled == pytest.approx(expected, abs=0.3)


def test_malformed_replies_are_counted_and_skipped(rig):
    dev, hw, hand = rig
    dev.open()
    home(dev, hand)
    loop.run(dev, 0.3)
    dev.read()
    injected = [b"\x00\x13junk", b"<AAAAAAAZAAAAAA>", b"<AAAAAAAAAAAAAAAAAA>", b"<AAAA", b"[AAAAAAAAAAAAAA>"]
    before = dev.rejected_frames
    for bad in injected:
        hw.inject_before_reply = [bad]
        dev.write_force([0, 0, 0])
        state = dev.read()
        np.testing.assert_allclose(state.position_mm, hw.stylus.position, atol=0.1)
    assert dev.rejected_frames - before == len(injected)
    assert dev.info.details["rejected_frames"] == dev.rejected_frames


def test_pulling_the_cable_faults_at_once_and_recovers(rig):
    dev, hw, hand = rig
    dev.open()
    home(dev, hand)
    dev.read()
    # replugged, a Falcon is freshly powered: loader mode, not homed
    state = loop.pull_the_cable(dev, hw.unplug, hw.replug, command=[1.0, 0.0, 0.0])
    assert dev.firmware_uploads == 2
    assert not state.calibrated
    dev.write_force([0.0, 3.0, 0.0])
    assert hw.motor == [0, 0, 0]
    home(dev, hand)


def test_a_silent_device_is_a_timeout_fault_not_a_hang(rig):
    dev, hw, _hand = rig
    dev.open()
    dev.read()
    hw.running = False  # the firmware stops answering frames
    t0 = time.monotonic()
    with pytest.raises(DeviceFault, match="did not answer"):
        dev.read()
    assert time.monotonic() - t0 < 1.0
