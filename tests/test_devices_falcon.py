"""Novint Falcon: the driver in closed loop against the emulated Falcon
(tests/emulators/falcon_*.py, written from libnifalcon only), and through the CLI. The
known-answer checks of its wire format and kinematics are in test_devices_falcon_known.py.

libnifalcon = github.com/libnifalcon/libnifalcon at commit f7c727a.
"""

from __future__ import annotations

import os
import time

import numpy as np
import pytest
from sasprobe.devices.base import DeviceFault, DeviceOpenError
from sasprobe.devices.falcon import models as M
from sasprobe.devices.falcon import protocol as P
from sasprobe.devices.falcon.driver import FalconDevice

from tests.conftest import run_cli
from tests.emulators.falcon_device import FalconHardware, Hand
from tests.emulators.falcon_usb import EmulatedUsbBackend, launch

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
        assert (
            hw.running
            and hw.probes_seen == 6
            and hw.upload_attempts == 1
            and dev.firmware_uploads == 1
        )
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
        FalconDevice(
            tmp_path / "nope.bin", usb_backend=EmulatedUsbBackend(FalconHardware(image))
        ).open()
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
    for move in [
        (10, 0, 0),
        (-10, 0, 0),
        (0, 10, 0),
        (0, -10, 0),
        (0, 0, 10),
        (0, 0, -10),
        (7, -7, 7),
    ]:
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
    for where, force in [
        ((0, 0, 0), (0, 0, 2.0)),
        ((0, 0, 0), (0, 0, -2.0)),
        ((15, -10, 5), (1.0, 2.0, -3.0)),
        ((-20, 20, -20), (-2.5, 0.5, 1.5)),
        ((25, 5, 25), (3.0, -3.0, 0.0)),
    ]:
        hand.target = where
        run_loop(dev, 0.4)
        run_loop(dev, 0.05, force_of=lambda _, force=force: np.asarray(force))
        exerted = hw.samples[-1].force_n
        cosine = exerted @ force / np.linalg.norm(exerted) / np.linalg.norm(force)
        assert cosine >= 0.999, (where, force, exerted)
        assert np.linalg.norm(exerted) == pytest.approx(np.linalg.norm(force), rel=0.01)


def test_forces_never_exceed_the_declared_limit(firmware):
    dev, hw, hand = make_rig(firmware, hand_stiffness_n_per_mm=5.0)  # a firm grip
    dev.open()
    home(dev, hand)
    rng = np.random.default_rng(7)
    commands = [rng.normal(size=3) * 100.0 for _ in range(100)] + [
        [np.nan, 1.0, 1.0],
        [np.inf, 0, 0],
        [1e300] * 3,
    ]
    for command in commands:
        assert max(abs(m) for m in dev.motor_command(command)) <= M.MOTOR_COMMAND_LIMIT
        run_loop(dev, 0.003, force_of=lambda _, c=command: np.asarray(c, dtype=float))
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
    telling = 0
    for _ in range(60):  # every read from now on describes the grip as the newest reply does
        hand.target = tuple(rng.uniform(-15.0, 15.0, size=3))
        run_loop(dev, 0.04)  # the grip is on its way there
        time.sleep(0.005)  # no frame goes out meanwhile: the reply to the last one is in
        state = dev.read()
        np.testing.assert_allclose(state.position_mm, hw.stylus.position, atol=0.05)
        # a read one reply behind would be off by this much: the read tells them apart where
        # the grip moved more than the tolerance (a starved test process may find it at rest)
        telling += np.linalg.norm(hw.samples[-1].grip_mm - hw.samples[-2].grip_mm) > 0.05
        if telling == 15:
            break
    assert telling == 15


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
    injected = [
        b"\x00\x13junk",
        b"<AAAAAAAZAAAAAA>",
        b"<AAAAAAAAAAAAAAAAAA>",
        b"<AAAA",
        b"[AAAAAAAAAAAAAA>",
    ]
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


@pytest.mark.parametrize(
    "options, with_firmware, message",
    [
        ({"loader_silent": True}, True, "loader did not answer 100 probes"),
        ({}, False, "no firmware running"),
    ],
)
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
