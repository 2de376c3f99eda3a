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
from tests.support.driver_loop import balance, read_until, settle_against_a_wall

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


def loop_until(dev, condition, force_of=None, timeout_s=30.0):
    """Run the loop until `condition(state)` holds for a state read; that state. (A wait for
    the condition: a busy machine runs fewer ticks in a given time.)"""
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        states, _ = run_loop(dev, 0.02, force_of)
        if states and condition(states[-1]):
            return states[-1]
    raise AssertionError("condition not reached in time")


def read_with_every_reply_in(dev, hw, timeout_s=30.0):
    """A read made with no frame going out, once the host holds the reply to the last one (a
    busy machine may take a while to read it), and where the grip is then."""
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        replies = hw.replies
        if hw.replies_taken():
            state, grip = dev.read(), hw.stylus.position.copy()
            if hw.replies == replies:  # else a frame handed over earlier went out meanwhile
                return state, grip
        time.sleep(0.001)
    raise AssertionError("the host never took every reply")


def command_carried_out(dev, hw, force, timeout_s=30.0):
    """Tick asking for `force` until the emulated motors carry out a command the driver
    computed for it where the grip was when it arrived; that command's sample. (A command
    computed from a reply the grip has since moved on from renders the force of another
    pose: on a busy machine the grip may travel far between the two.)"""
    asked = {}  # motor command -> where the driver computed it
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        try:
            state = dev.read()
        except DeviceFault:
            dev.write_force(ZERO)
        else:
            asked[tuple(dev.motor_command(force))] = state.position_mm
            dev.write_force(force)
        for sample in list(hw.samples)[-10:]:
            where = asked.get(sample.motor)
            if where is not None and np.allclose(sample.grip_mm, where, atol=0.1):
                return sample
        time.sleep(0.001)
    raise AssertionError(f"no command for {force} carried out where it was computed")


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
    assert not read_until(dev, lambda s: True).calibrated
    home(dev, hand)
    loop_until(dev, lambda s: hw.motor != (0, 0, 0), lambda s: np.array([0.0, 3.0, 0.0]))
    assert read_until(dev, lambda s: True).calibrated and hw.leds == P.LED_GREEN and hw.homing
    assert hw.homing_losses == 0 and hw.refused == 0


def at_rest(dev, hw, hand, target):
    """Move the hand to `target` and run the loop until the grip rests there (the hand holds
    it within 0.05 mm) and the driver has read it; the state read then."""
    hand.target = target
    return loop_until(
        dev,
        lambda s: (
            np.allclose(hw.stylus.position, target, atol=0.05)
            and np.allclose(s.position_mm, hw.stylus.position, atol=0.1)
        ),
    )


def test_each_axis_and_a_diagonal_are_reported_as_moved(rig):
    dev, hw, hand = rig
    dev.open()
    home(dev, hand)
    origin = at_rest(dev, hw, hand, (0.0, 0.0, 0.0)).position_mm
    for move in [
        (10, 0, 0),
        (-10, 0, 0),
        (0, 10, 0),
        (0, -10, 0),
        (0, 0, 10),
        (0, 0, -10),
        (7, -7, 7),
    ]:
        state = at_rest(dev, hw, hand, move)
        # (at_rest read it within 0.1 mm of the grip; the grip may settle on after that read)
        np.testing.assert_allclose(state.position_mm - origin, move, atol=0.5)
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
        at_rest(dev, hw, hand, where)
        sample = command_carried_out(dev, hw, np.asarray(force))
        exerted = sample.force_n
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
        sample = command_carried_out(dev, hw, np.asarray(command, dtype=float))
        # carried out within 0.1 mm of where it was computed: the force of fixed motor
        # commands changes by about 1 % per mm there
        assert np.linalg.norm(sample.force_n) <= M.FALCON_LIMITS.max_force_n * 1.02
    run_loop(dev, 0.01, force_of=lambda s: np.array([np.nan] * 3))
    dev.close()
    assert hw.motor == (0, 0, 0) and hw.refused == 0


def test_a_virtual_wall_settles_where_the_springs_balance(rig):
    dev, hw, hand = rig
    dev.open()
    home(dev, hand)
    hand.target = (20.0, 0.0, 0.0)
    x = settle_against_a_wall(dev)
    assert x == pytest.approx(balance(20.0, hw.stylus.hand_k), abs=0.3)


def test_a_200_ms_stall_is_survived_with_fresh_reads_after(rig):
    dev, hw, hand = rig
    dev.open()
    home(dev, hand)
    hand.target = (5.0, 5.0, 5.0)
    run_loop(dev, 0.3)
    hw.stall()
    hand.target = (-5.0, 0.0, 10.0)  # the hand moves on meanwhile
    stalled_at, faults, reads_s = time.monotonic(), [], []
    while not faults or time.monotonic() - stalled_at < 0.2:  # (a busy machine ticks less)
        assert time.monotonic() - stalled_at < 30.0, "no fault while the Falcon is silent"
        t0 = time.monotonic()
        try:
            dev.read()
        except DeviceFault as exc:
            faults.append(str(exc))
        reads_s.append(time.monotonic() - t0)
        dev.write_force(ZERO)
        time.sleep(0.001)
    hw.answer_again()
    assert all("has not answered" in f for f in faults)
    # no read waited for the Falcon: one that did would take the 20 ms reply timeout
    assert np.median(reads_s) < dev.reply_timeout_ns / 2e9
    fresh = 0  # it answers again: reads come back by themselves
    while fresh < 100:
        assert time.monotonic() - stalled_at < 60.0, "no reads came back after the stall"
        states, faults = run_loop(dev, 0.02)
        assert all("has not answered" in f for f in faults)
        fresh += len(states)
    assert hw.refused == 0 and hw.homing_losses == 0
    rng = np.random.default_rng(3)
    telling = 0
    for _ in range(200):  # every read from now on describes the grip as the newest reply does
        hand.target = tuple(rng.uniform(-15.0, 15.0, size=3))
        run_loop(dev, 0.04)  # the grip is on its way there
        state, grip = read_with_every_reply_in(dev, hw)
        np.testing.assert_allclose(state.position_mm, grip, atol=0.05)
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
    faults, deadline = [], time.monotonic() + 10.0
    while len(faults) < 20:  # the daemon's ticks, faulted for 20 ticks
        assert time.monotonic() < deadline, "no fault from a silent Falcon"
        faults += run_loop(dev, 0.01, force_of=lambda s: np.array([0.0, 0.0, 2.0]))[1]
    assert len(set(f.split(" for ")[0] for f in faults)) == 1 and "\n" not in faults[-1]
    assert dev.motor == [0, 0, 0]  # what it sends while silent
    probes = hw.probes_seen
    waits = []
    for _ in range(5):
        t0 = time.monotonic()
        with pytest.raises(DeviceFault, match="still unavailable.*USB link is up"):
            dev.reconnect()
        waits.append(time.monotonic() - t0)
    assert hw.probes_seen == probes  # no firmware reload into it
    assert min(waits) < 0.1  # it waits for nothing (a busy machine may delay any one call)


def test_pulling_the_cable_faults_at_once_and_recovers(rig):
    dev, hw, hand = rig
    dev.open()
    home(dev, hand)
    hw.unplug()
    faults, deadline = [], time.monotonic() + 10.0
    while not faults or "USB link failed" not in faults[-1]:
        assert time.monotonic() < deadline, faults[-1:]
        faults += run_loop(dev, 0.005)[1]
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
        loop_until(dev, lambda s: not hw.inject_before_reply)  # sent ahead of a reply
        state, grip = read_with_every_reply_in(dev, hw)
        np.testing.assert_allclose(state.position_mm, grip, atol=0.1)
    assert dev.rejected_frames - before == len(injected)
    assert dev.info.details["rejected_frames"] == dev.rejected_frames


def test_buttons_come_through(rig):
    dev, hw, _hand = rig
    dev.open()
    hw.buttons = 0b0101
    loop_until(dev, lambda s: s.buttons == 0b0101)


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
