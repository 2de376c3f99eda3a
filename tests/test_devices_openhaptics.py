"""OpenHaptics driver through ctypes against the stand-in HD library (fake_libhd.c).

Expected behaviour is that of the SDK's own examples (danepowell/openhaptics, commit
2ce9a48, examples/HD/console): Calibration.c prefers auto over inkwell over encoder
reset and resets the encoders before the scheduler, at the reset pose;
AnchoredSpringForce.c stops force output on a force error and ends the callback on a
scheduler error (when force comes back after a force error:
test_devices_openhaptics_resume.py).
"""

from __future__ import annotations

import math
import re
import shutil
import subprocess
import time

import numpy as np
import pytest
from sasprobe.devices.base import DeviceFault, DeviceOpenError
from sasprobe.devices.openhaptics import hdapi
from sasprobe.devices.openhaptics.driver import OpenHapticsDevice, create

from tests.emulators import libhd
from tests.emulators.libhd import (
    HD_CALIBRATION_AUTO,
    HD_CALIBRATION_ENCODER_RESET,
    HD_CALIBRATION_INKWELL,
    HD_COMM_ERROR,
    HD_DEVICE_FAULT,
    HD_EXCEEDED_MAX_FORCE,
    HD_EXCEEDED_MAX_FORCE_IMPULSE,
    HD_EXCEEDED_MAX_VELOCITY,
    HD_FORCE_ERROR,
    HD_INVALID_ENUM,
    HD_WARM_MOTORS,
    UNCALIBRATED_OFFSET,
    USABLE_BOX_CENTRE,
)
from tests.support.driver_loop import read_until


def device_frame(library_mm):
    return np.asarray(library_mm) - np.asarray(USABLE_BOX_CENTRE)


def test_open_reads_the_nominal_limits_and_recentres_the_workspace(hd_arm):
    dev, emu = hd_arm(styles=HD_CALIBRATION_INKWELL, hand=(10.0, -5.0, -20.0))
    dev.open()
    lim = dev.info.limits
    assert (lim.max_force_n, lim.continuous_force_n, lim.max_stiffness_n_per_mm) == (3.3, 0.88, 0.5)
    assert lim.max_damping_n_s_per_m == pytest.approx(4.0)  # 0.004 N·s/mm
    # the library's usable box is z -70..0: the device frame puts its centre at the origin
    assert lim.workspace_min_mm == (-80.0, -60.0, -35.0) and lim.workspace_max_mm == (
        80.0,
        60.0,
        35.0,
    )
    assert dev.info.model == "Touch (emulated)"
    state = read_until(dev, lambda s: True)
    assert not state.calibrated  # uncalibrated encoders read off by the emulator's offset
    np.testing.assert_allclose(
        state.position_mm, device_frame(np.subtract((10.0, -5.0, -20.0), UNCALIBRATED_OFFSET))
    )
    emu.control.inkwell = 1
    state = read_until(dev, lambda s: s.calibrated)
    np.testing.assert_allclose(state.position_mm, [10.0, -5.0, 15.0])


@pytest.mark.parametrize(
    "supported, chosen",
    [
        (
            HD_CALIBRATION_AUTO | HD_CALIBRATION_INKWELL | HD_CALIBRATION_ENCODER_RESET,
            HD_CALIBRATION_AUTO,
        ),
        (HD_CALIBRATION_INKWELL | HD_CALIBRATION_ENCODER_RESET, HD_CALIBRATION_INKWELL),
        (HD_CALIBRATION_AUTO | HD_CALIBRATION_ENCODER_RESET, HD_CALIBRATION_AUTO),
        (HD_CALIBRATION_AUTO | HD_CALIBRATION_INKWELL, HD_CALIBRATION_AUTO),
    ],
)
def test_calibration_prefers_auto_then_inkwell_then_encoder_reset(hd_arm, supported, chosen):
    dev, emu = hd_arm(styles=supported, inkwell=True)
    dev.open()
    read_until(dev, lambda s: s.calibrated)
    assert dev.calibration_style == chosen and emu.control.last_update_style == chosen
    assert emu.control.resets == 0  # an encoder reset was never needed, so never done


def test_inkwell_calibration_gates_force(hd_arm):
    dev, emu = hd_arm(styles=HD_CALIBRATION_INKWELL)
    dev.open()
    assert not read_until(dev, lambda s: True).calibrated
    dev.write_force([1.0, 0.0, 0.0])
    emu.wait_frames(20)
    assert emu.applied_force == (0.0, 0.0, 0.0)  # no force until calibrated
    assert emu.control.calibration == libhd.HD_CALIBRATION_NEEDS_MANUAL_INPUT
    emu.control.inkwell = 1  # NEEDS_MANUAL_INPUT → NEEDS_UPDATE → hdUpdateCalibration(INKWELL) → OK
    read_until(dev, lambda s: s.calibrated)
    dev.write_force([1.0, 0.0, 0.0])
    state = read_until(dev, lambda s: s.position_mm[0] > 1.0)
    assert emu.applied_force == (1.0, 0.0, 0.0)
    assert state.position_mm[0] == pytest.approx(
        1.0 / libhd.HAND_STIFFNESS_N_PER_MM
    )  # the hand gives way 2 mm


def test_the_encoder_reset_comes_before_the_scheduler_at_the_held_pose(hd_arm):
    dev, emu = hd_arm(
        styles=HD_CALIBRATION_ENCODER_RESET, hand=(0.0, 0.0, 0.0), reset_encoders=True
    )
    dev.open()  # the user holds the arm at its reset pose (the emulator's origin) and says so
    assert (emu.control.resets, emu.control.resets_while_running) == (1, 0)
    assert emu.control.reset_distance_mm == 0.0
    assert read_until(dev, lambda s: True).calibrated
    emu.hand.target = (10.0, -5.0, -20.0)
    state = read_until(dev, lambda s: s.position_mm[0] == 10.0)
    np.testing.assert_allclose(state.position_mm, device_frame((10.0, -5.0, -20.0)))
    emu.wait_frames(50)
    assert emu.control.resets == 1  # never again from the servo loop


def test_an_encoder_reset_arm_is_refused_until_the_user_holds_the_reset_pose(hd_arm):
    dev, emu = hd_arm(styles=HD_CALIBRATION_ENCODER_RESET, hand=(20.0, 30.0, -10.0))
    with pytest.raises(
        DeviceOpenError, match=r"needs an encoder reset.*reset position.*openhaptics:reset-encoders"
    ):
        dev.open()
    assert emu.control.resets == 0 and emu.control.scheduler_running == 0


def test_a_reconnect_never_resets_the_encoders_at_an_unknown_pose(hd_arm):
    dev, emu = hd_arm(styles=HD_CALIBRATION_ENCODER_RESET, reset_encoders=True)
    dev.open()
    read_until(dev, lambda s: s.calibrated)
    emu.unplug()  # power lost: the encoders forget their zero
    with pytest.raises(DeviceFault, match="HD_COMM_ERROR"):
        _until_fault(dev)
    emu.hand.target = (25.0, 10.0, -30.0)  # wherever the user put it down
    emu.replug()
    with pytest.raises(DeviceFault, match="needs an encoder reset"):
        dev.reconnect()
    assert emu.control.resets == 1


def calibrated_and_pushing(hd_arm, force=(1.0, 0.0, 0.0)):
    dev, emu = hd_arm(styles=HD_CALIBRATION_AUTO)
    dev.open()
    read_until(dev, lambda s: s.calibrated)
    dev.write_force(force)
    emu.wait_frames(5)
    assert emu.applied_force == force
    return dev, emu


@pytest.mark.parametrize(
    "code",
    [
        HD_WARM_MOTORS,
        HD_EXCEEDED_MAX_FORCE,
        HD_EXCEEDED_MAX_VELOCITY,
        HD_FORCE_ERROR,
        HD_DEVICE_FAULT,
    ],
)
def test_a_force_error_stops_only_force_output(hd_arm, code):
    dev, emu = calibrated_and_pushing(hd_arm)
    emu.inject(code)
    emu.wait_frames(5)
    dev.write_force([1.0, 0.0, 0.0])  # the daemon still asks for force ...
    emu.wait_frames(5)
    assert emu.applied_force == (0.0, 0.0, 0.0)  # ... the arm gets none
    frames = emu.control.frames
    state = dev.read()  # no fault: the servo loop goes on
    assert state.calibrated and emu.control.callback_done == 0
    emu.wait_frames(5)
    assert emu.control.frames > frames
    assert dev.info.details["force_errors"] == 1 and dev.info.details["force_stopped"] is True


def test_the_force_impulse_warning_is_not_a_force_error(hd_arm):
    """hduIsForceError (libHDU's hduError.o) names warm motors, max force, max velocity and
    force errors, not HD_EXCEEDED_MAX_FORCE_IMPULSE: the library's own impulse check has
    already limited the change in force."""
    dev, emu = calibrated_and_pushing(hd_arm)
    emu.inject(HD_EXCEEDED_MAX_FORCE_IMPULSE)
    emu.wait_frames(5)
    dev.read()
    dev.write_force((0.5, 0.0, 0.0))
    emu.wait_frames(5)
    assert emu.applied_force == (0.5, 0.0, 0.0)
    assert dev.info.details["other_errors"] == 1 and dev.info.details["force_errors"] == 0


def test_other_errors_are_counted_and_force_goes_on(hd_arm):
    dev, emu = calibrated_and_pushing(hd_arm)
    emu.inject(HD_INVALID_ENUM)
    emu.wait_frames(5)
    dev.read()
    assert emu.applied_force == (1.0, 0.0, 0.0)
    assert dev.info.details["other_errors"] == 1 and dev.info.details["force_errors"] == 0


def test_a_scheduler_error_ends_the_callback_and_is_a_fault(hd_arm):
    dev, emu = calibrated_and_pushing(hd_arm)
    emu.inject(
        HD_COMM_ERROR
    )  # the device itself stays powered: its motors keep what they were last sent
    with pytest.raises(DeviceFault, match=r"HD_COMM_ERROR \(0x0302"):
        _until_fault(dev)
    deadline = time.monotonic() + 2.0
    while not emu.control.callback_done:
        assert time.monotonic() < deadline, "the servo callback did not end"
        time.sleep(0.001)
    frames = emu.control.frames
    time.sleep(0.02)
    assert emu.control.frames == frames  # no frame runs any more ...
    assert emu.applied_force == (0.0, 0.0, 0.0)  # ... and the erring one turned the motors off


def test_a_scheduler_error_turns_the_motors_off_before_the_callback_returns(hd_arm):
    """Nothing may depend on the library calling the callback again after a communication
    error: here it does not, so what the erring callback left is what the arm renders."""
    dev, emu = calibrated_and_pushing(hd_arm)
    emu.control.stop_calls_on_error = 1
    emu.inject(HD_COMM_ERROR)
    with pytest.raises(DeviceFault, match="HD_COMM_ERROR"):
        _until_fault(dev)
    deadline = time.monotonic() + 2.0
    while not emu.control.halted:
        assert time.monotonic() < deadline, "the scheduler did not stop calling"
        time.sleep(0.001)
    assert emu.applied_force == (0.0, 0.0, 0.0) and emu.control.force_enabled == 0


def test_a_vanished_arm_faults_and_recovers_when_back(hd_arm):
    dev, emu = calibrated_and_pushing(hd_arm)
    emu.unplug()
    with pytest.raises(DeviceFault, match=r"HD_COMM_ERROR \(0x0302"):
        _until_fault(dev)
    assert emu.applied_force == (0.0, 0.0, 0.0)  # the motors are off
    with pytest.raises(DeviceFault, match="still unavailable.*HD_COMM_ERROR"):
        dev.reconnect()
    emu.replug()
    dev.reconnect()
    read_until(dev, lambda s: s.calibrated)  # auto calibration again after the power cycle


def _until_fault(dev, timeout_s=2.0):
    """Keep reading (as the daemon would) until the driver raises; it must within the timeout."""
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        dev.read()
        time.sleep(0.002)


def test_forces_never_exceed_the_nominal_maximum(hd_arm):
    dev, emu = calibrated_and_pushing(hd_arm)
    rng = np.random.default_rng(5)
    for command in [rng.normal(size=3) * 50 for _ in range(50)] + [[np.nan, 0, 0], [np.inf, 1, 1]]:
        dev.write_force(command)
        time.sleep(0.002)
    dev.read()
    assert emu.control.forces_clamped == 0  # the driver clamped first: the library never had to
    assert emu.control.max_force <= 3.3 + 1e-12


def test_close_leaves_the_motors_at_zero(hd_arm):
    dev, emu = calibrated_and_pushing(hd_arm)
    dev.close()
    assert emu.applied_force == (0.0, 0.0, 0.0) and dev.last_force_n.tolist() == [0.0, 0.0, 0.0]


def test_transform_buttons_and_servo_rate(hd_arm):
    dev, emu = hd_arm(styles=HD_CALIBRATION_AUTO)
    dev.open()
    emu.control.yaw = 0.5
    emu.control.buttons = 0b11
    read_until(dev, lambda s: s.buttons == 0b11)
    state = read_until(dev, lambda s: abs(s.orientation[2]) > 0.1)
    np.testing.assert_allclose(
        state.orientation, [math.cos(0.25), 0.0, math.sin(0.25), 0.0], atol=1e-12
    )
    ticks = dev.servo_ticks
    time.sleep(0.2)
    assert dev.servo_ticks - ticks > 20  # the library's scheduler thread keeps calling us


def test_a_stalled_servo_loop_is_a_fault(hd_arm):
    dev, emu = hd_arm(styles=HD_CALIBRATION_AUTO)
    dev.open()
    read_until(dev, lambda s: True)
    dev._lib.hdStopScheduler()
    time.sleep(0.1)
    with pytest.raises(DeviceFault, match="servo loop has not run"):
        dev.read()


def test_unknown_device_name(hd_arm):
    dev, _emu = hd_arm(name="Left Arm")
    with pytest.raises(
        DeviceOpenError, match="could not initialise 'Left Arm'.*HD_COMM_CONFIG_ERROR"
    ):
        dev.open()


def test_the_device_string():
    assert (create(None).name, create(None).reset_encoders) == (None, False)
    assert (
        create("reset-encoders").name,
        create("reset-encoders").reset_encoders,
    ) == (None, True)
    named = create("Left Arm:reset-encoders")
    assert (named.name, named.reset_encoders) == ("Left Arm", True)
    assert create("Default PHANToM").name == "Default PHANToM"


def test_missing_library_says_so_in_one_line(monkeypatch, tmp_path):
    monkeypatch.delenv("SASPROBE_HD_LIBRARY", raising=False)
    with pytest.raises(DeviceOpenError, match="OpenHaptics is not installed") as err:
        OpenHapticsDevice(library=str(tmp_path / "libHD.so")).open()
    assert "\n" not in str(err.value)


def test_a_library_without_the_hd_entry_points_is_refused(hd_library, tmp_path):
    not_hd = tmp_path / "libnot.so"
    subprocess.run(
        [shutil.which("cc") or "gcc", "-shared", "-fPIC", "-o", str(not_hd), "-x", "c", "-"],
        input=b"int x;",
        check=True,
        capture_output=True,
        timeout=120,
    )
    with pytest.raises(DeviceOpenError, match="is not the OpenHaptics HD library"):
        hdapi.load_library(str(not_hd))


def test_the_stand_in_and_the_driver_transcribed_hddefines_alike():
    """Two transcriptions of hdDefines.h (the emulator's C, the driver's Python) must agree."""

    def value(text):
        shift = re.fullmatch(r"\(1 << (\d+)\)", text)
        return 1 << int(shift.group(1)) if shift else int(text, 0)

    defines = {
        name: value(text)
        for name, text in re.findall(
            r"^#define (HD_\w+) (\(1 << \d+\)|0x[0-9A-Fa-f]+|\d+)$", libhd.SOURCE.read_text(), re.M
        )
    }
    assert len(defines) > 25
    shared = {name: value for name, value in defines.items() if hasattr(hdapi, name)}
    assert shared == {name: getattr(hdapi, name) for name in shared} and len(shared) > 15
    named = {name: code for code, name in hdapi.HD_ERRORS.items()}
    assert all(named[name] == value for name, value in defines.items() if name in named)
