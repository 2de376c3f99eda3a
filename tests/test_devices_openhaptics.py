"""OpenHaptics driver through ctypes against a stand-in HD library compiled from C."""

from __future__ import annotations

import ctypes
import math
import shutil
import subprocess
import time

import numpy as np
import pytest

from sasprobe.devices import openhaptics as O
from sasprobe.devices.base import DeviceFault, DeviceOpenError
from tests.emulators.libhd import build as build_libhd


@pytest.fixture(scope="module")
def libhd(tmp_path_factory):
    out = build_libhd(tmp_path_factory.mktemp("libhd"))
    if out is None:
        pytest.skip("no C compiler to build the stand-in HD library")
    fake = ctypes.CDLL(str(out))
    fake.fake_set_hand.argtypes = [ctypes.c_double] * 3
    fake.fake_set_yaw.argtypes = [ctypes.c_double]
    fake.fake_max_force_seen.restype = ctypes.c_double
    fake.fake_forces_exceeding.restype = ctypes.c_long
    fake.fake_callbacks_run.restype = ctypes.c_long
    return str(out), fake


@pytest.fixture
def rig(libhd):
    path, fake = libhd
    fake.fake_reset()
    dev = O.OpenHapticsDevice(library=path)
    yield dev, fake
    dev.close()


def wait_for(dev, condition, timeout_s=5.0):
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        try:
            state = dev.read()
            if condition(state):
                return state
        except DeviceFault:
            pass
        time.sleep(0.005)
    raise AssertionError("condition not reached in time")


def library_force(fake):
    out = (ctypes.c_double * 3)()
    fake.fake_force(out)
    return np.array(out[:])


def test_open_reads_the_nominal_limits_and_recentres_the_workspace(rig):
    dev, fake = rig
    dev.open()
    lim = dev.info.limits
    assert (lim.max_force_n, lim.continuous_force_n, lim.max_stiffness_n_per_mm) == (3.3, 0.88, 0.5)
    assert lim.max_damping_n_s_per_m == pytest.approx(4.0)  # 0.004 N·s/mm
    # the library's usable box is z -70..0: the device frame puts its centre at the origin
    assert lim.workspace_min_mm == (-80.0, -60.0, -35.0) and lim.workspace_max_mm == (80.0, 60.0, 35.0)
    assert dev.info.model == "Touch (emulated)"
    fake.fake_set_hand(10.0, -5.0, -20.0)
    state = wait_for(dev, lambda s: s.position_mm[0] == 10.0)
    assert state.position_mm.tolist() == [10.0, -5.0, -20.0 + 35.0]


def test_inkwell_calibration_gates_force(rig):
    dev, fake = rig
    dev.open()
    state = wait_for(dev, lambda s: True)
    assert not state.calibrated
    dev.write_force([1.0, 0.0, 0.0])
    time.sleep(0.02)
    assert np.allclose(library_force(fake), 0.0)  # no force until calibrated
    fake.fake_put_in_inkwell()  # NEEDS_MANUAL_INPUT → NEEDS_UPDATE → hdUpdateCalibration → OK
    wait_for(dev, lambda s: s.calibrated)
    dev.write_force([1.0, 0.0, 0.0])
    state = wait_for(dev, lambda s: s.position_mm[0] > 1.0)
    np.testing.assert_allclose(library_force(fake), [1.0, 0.0, 0.0])
    assert state.position_mm[0] == pytest.approx(1.0 / 0.5)  # the hand's 0.5 N/mm spring gives way 2 mm


def test_transform_buttons_and_servo_rate(rig):
    dev, fake = rig
    dev.open()
    fake.fake_set_yaw(ctypes.c_double(0.5))
    fake.fake_set_buttons(0b11)
    state = wait_for(dev, lambda s: s.buttons == 0b11)
    state = wait_for(dev, lambda s: abs(s.orientation[2]) > 0.1)
    np.testing.assert_allclose(state.orientation, [math.cos(0.25), 0.0, math.sin(0.25), 0.0], atol=1e-12)
    ticks = dev.servo_ticks
    time.sleep(0.2)
    assert dev.servo_ticks - ticks > 20  # the library's scheduler thread keeps calling us


def test_forces_never_exceed_the_nominal_maximum(rig):
    dev, fake = rig
    dev.open()
    fake.fake_put_in_inkwell()
    wait_for(dev, lambda s: s.calibrated)
    rng = np.random.default_rng(5)
    for command in [rng.normal(size=3) * 50 for _ in range(50)] + [[np.nan, 0, 0], [np.inf, 1, 1]]:
        dev.write_force(command)
        time.sleep(0.002)
    dev.read()
    assert fake.fake_forces_exceeding() == 0
    assert fake.fake_max_force_seen() <= 3.3 + 1e-12


def test_an_hd_error_is_a_fault_naming_the_code_and_recovery_follows(rig):
    dev, fake = rig
    dev.open()
    wait_for(dev, lambda s: True)
    fake.fake_unplug()
    with pytest.raises(DeviceFault, match=r"HD_COMM_ERROR \(0x0302"):
        _until_fault(dev)
    with pytest.raises(DeviceFault, match="HD_COMM_CONFIG_ERROR"):
        dev.reconnect()
    fake.fake_replug()
    dev.reconnect()
    wait_for(dev, lambda s: True)


def _until_fault(dev, timeout_s=2.0):
    """Keep reading (as the daemon would) until the driver raises; it must within the timeout."""
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        dev.read()
        time.sleep(0.002)


def test_a_stalled_servo_loop_is_a_fault(rig):
    dev, fake = rig
    dev.open()
    wait_for(dev, lambda s: True)
    dev._lib.hdStopScheduler()
    time.sleep(0.1)
    with pytest.raises(DeviceFault, match="servo loop has not run"):
        dev.read()


def test_unknown_device_name(rig, libhd):
    path, _fake = libhd
    with pytest.raises(DeviceOpenError, match="could not initialise 'Left Arm'.*HD_COMM_CONFIG_ERROR"):
        O.OpenHapticsDevice("Left Arm", library=path).open()


def test_missing_library_says_so_in_one_line(monkeypatch, tmp_path):
    monkeypatch.delenv("SASPROBE_HD_LIBRARY", raising=False)
    with pytest.raises(DeviceOpenError, match="OpenHaptics is not installed") as err:
        O.OpenHapticsDevice(library=str(tmp_path / "libHD.so")).open()
    assert "\n" not in str(err.value)

def test_a_library_without_the_hd_entry_points_is_refused(libhd, tmp_path):
    not_hd = tmp_path / "libnot.so"
    subprocess.run([shutil.which("cc") or "gcc", "-shared", "-fPIC", "-o", str(not_hd), "-x", "c", "-"],
                   input=b"int x;", check=True, capture_output=True, timeout=120)
    with pytest.raises(DeviceOpenError, match="is not the OpenHaptics HD library"):
        O.load_library(str(not_hd))
