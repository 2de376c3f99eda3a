"""Transports over real ptys and pyusb, plus the shared safety helpers."""

from __future__ import annotations

import os
import time

import numpy as np
import pytest
from hypothesis import example, given, settings
from hypothesis import strategies as st
from sasprobe.devices.base import DeviceFault, DeviceOpenError
from sasprobe.devices.hardware import VelocityFilter, clamp_force
from sasprobe.devices.kinematics import quaternion_from_matrix
from sasprobe.devices.transports import SerialTransport, UsbTransport

from tests.emulators.falcon_usb import EmulatedUsbBackend, FalconHardware
from tests.emulators.pty_serial import PtySerialDevice


class Echo(PtySerialDevice):
    """Answers every byte with itself: enough to exercise the transport."""

    def loop(self) -> None:
        data = bytes([self.wait_byte()])
        while self.available():
            data += bytes([self.read()])
        self.write(data)


def read_at_least(port, n, timeout_s=2.0) -> bytes:
    got, deadline = b"", time.monotonic() + timeout_s
    while len(got) < n and time.monotonic() < deadline:
        got += port.read(64, 0.1)
    return got


@pytest.fixture
def echo(tmp_path):
    dev = Echo(tmp_path)
    yield dev
    dev.stop()


def test_serial_round_trip_and_read_timeout(echo):
    with SerialTransport(echo.path) as port:
        port.write(b"hello")
        assert read_at_least(port, 5) == b"hello"
        t0 = time.monotonic()
        assert port.read(64, 0.05) == b""  # nothing came: empty, not a hang
        assert time.monotonic() - t0 < 1.0


def test_a_pulled_serial_cable_is_a_fault_and_the_port_comes_back(echo):
    port = SerialTransport(echo.path)
    port.open()
    echo.unplug()
    with pytest.raises(DeviceFault, match="lost"):
        port.write(b"x")
        port.read(64, 0.5)
    port.close()
    with pytest.raises(DeviceOpenError, match="no such serial port"):
        port.open()
    echo.replug()
    port.open()
    port.write(b"back")
    assert read_at_least(port, 4) == b"back"
    port.close()


def test_a_write_that_went_out_is_no_fault_however_late_the_writer_looks_at_the_clock(
    echo, monkeypatch
):
    """A busy machine may deschedule the writer for longer than the write timeout just after
    its bytes went out: they went out all the same, so the port is not lost. (Here every
    look at the clock is 100 ms after the last, the write timeout is 50 ms.)"""
    import serial.serialutil

    with SerialTransport(echo.path) as port:
        looks = iter(range(10**6))
        late = staticmethod(lambda: next(looks) * 0.1)
        monkeypatch.setattr(serial.serialutil.Timeout, "TIME", late)
        monkeypatch.setattr(time, "monotonic", late)
        port.write(b"hello")
        monkeypatch.undo()
        assert read_at_least(port, 5) == b"hello"


def test_a_port_that_takes_no_bytes_is_a_fault_not_a_hang(echo):
    with SerialTransport(echo.path) as port:
        # nothing reads the line: the buffer fills, then a write waits out its timeout
        echo.go_silent()
        with pytest.raises(DeviceFault, match="lost: it took no bytes for 50 ms"):
            for _ in range(10**4):
                port.write(bytes(4096))


@pytest.mark.skipif(
    os.geteuid() == 0, reason="root opens any node; the CLI test drops the capability instead"
)
def test_permission_denied_names_the_fix(echo):
    os.chmod(os.path.realpath(echo.path), 0)
    with pytest.raises(DeviceOpenError, match="permission denied.*dialout.*udev rule"):
        SerialTransport(echo.path).open()


def test_usb_permission_and_absence(tmp_path):
    hw = FalconHardware(b"x" * 10)
    backend = EmulatedUsbBackend(hw)
    backend.access_denied = True
    usb = UsbTransport(0x0403, 0xCB48, 0x02, 0x81, backend=backend, label="Novint Falcon")
    with pytest.raises(
        DeviceOpenError, match="permission denied on the Novint Falcon.*plugdev.*udev rule"
    ):
        usb.open()
    backend.access_denied = False
    usb.open()
    hw.unplug()
    with pytest.raises(DeviceFault, match="lost"):
        usb.write(b"<")
    usb.close()
    with pytest.raises(DeviceOpenError, match="no Novint Falcon found"):
        usb.open()


def test_usb_without_an_emulator_is_a_clear_open_error():
    # here either libusb is missing or no Falcon is attached: both are one clear line
    with pytest.raises(DeviceOpenError) as err:
        UsbTransport(0x0403, 0xCB48, 0x02, 0x81, label="Novint Falcon").open()
    assert "libusb-1.0" in str(err.value) or "no Novint Falcon found" in str(err.value)


@settings(max_examples=300, deadline=None)
@given(
    st.lists(st.floats(allow_nan=True, allow_infinity=True), min_size=3, max_size=3),
    st.floats(0.1, 20.0),
)
@example([0.0, 0.0, 1.8e-161], 1.0)  # once found by hypothesis: the test's own norm underflowed
def test_clamp_force_is_finite_bounded_and_keeps_direction(force, limit):
    out = clamp_force(force, limit)
    assert np.all(np.isfinite(out)) and np.linalg.norm(out) <= limit * (1 + 1e-12)
    f = np.array(force)
    if np.all(np.isfinite(f)) and np.max(np.abs(f)) > 0 and np.linalg.norm(out) > 0:
        # compare scaled copies: squaring a tiny force underflows into denormals
        unit = f / np.max(np.abs(f))
        out_unit = out / np.max(np.abs(out))
        cosine = out_unit @ unit / np.linalg.norm(out_unit) / np.linalg.norm(unit)
        assert cosine == pytest.approx(1.0)
    with np.errstate(
        over="ignore"
    ):  # the norm of a huge test vector may overflow; the clamp's must not
        small = np.all(np.isfinite(f)) and np.linalg.norm(f) <= limit
    if small:
        np.testing.assert_array_equal(out, f)


def test_velocity_filter_converges_to_a_constant_velocity():
    filt = VelocityFilter(cutoff_hz=100.0)
    v = np.array([10.0, -5.0, 2.0])
    for k in range(200):
        est = filt.update(k * 1_000_000, v * k * 1e-3)
    np.testing.assert_allclose(est, v, rtol=1e-6)


@pytest.mark.parametrize("angle", [0.3, 2.0, 3.1, -2.5])
@pytest.mark.parametrize("axis", [(1, 0, 0), (0, 1, 0), (0, 0, 1), (1, 2, -2)])
def test_quaternion_from_matrix_matches_rodrigues(axis, angle):
    a = np.array(axis, float) / np.linalg.norm(axis)
    k = np.array([[0, -a[2], a[1]], [a[2], 0, -a[0]], [-a[1], a[0], 0]])
    m = np.eye(3) + np.sin(angle) * k + (1 - np.cos(angle)) * k @ k
    q = quaternion_from_matrix(m)
    expected = np.concatenate([[np.cos(angle / 2)], np.sin(angle / 2) * a])
    expected = expected if expected[0] >= 0 else -expected
    np.testing.assert_allclose(q, expected, atol=1e-12)
