"""Byte transports behind one small interface: serial (pyserial), HID (hidapi), USB (pyusb).

Every transport:
- `open()` raises DeviceOpenError with one line that says how to fix it (missing port,
  no permission: udev rule / group, busy, missing libusb);
- `read(max_bytes, timeout_s)` returns what arrived (one HID report, one USB packet, the
  bytes waiting on a serial port), or b"" when nothing came within the timeout: it never
  blocks longer than that;
- a device that went away (cable pulled, port closed, USB error) raises DeviceFault from
  `read`/`write`, so the daemon can zero the force and retry `open()`.
"""

from __future__ import annotations

import abc
import errno
import math
import os
import select
import time

from sasprobe.devices.base import DeviceFault, DeviceOpenError

UDEV_HINT = "install the udev rule from docs/connect-your-arm.md"


def permission_hint(path: str, group: str = "dialout") -> str:
    return (
        f"permission denied on {path}: add yourself to the '{group}' group "
        f"(sudo usermod -aG {group} $USER, then log in again) or {UDEV_HINT}"
    )


class Transport(abc.ABC):
    """A byte pipe to one device."""

    name: str = ""
    _handle = None  # the library's open port/device object

    @abc.abstractmethod
    def open(self) -> None: ...

    @abc.abstractmethod
    def close(self) -> None: ...

    @property
    def is_open(self) -> bool:
        return self._handle is not None

    def _require(self):
        if self._handle is None:
            raise DeviceFault(f"{self.name} is not open")
        return self._handle

    @abc.abstractmethod
    def write(self, data: bytes) -> None: ...

    @abc.abstractmethod
    def read(self, max_bytes: int, timeout_s: float) -> bytes: ...

    def discard_input(self, quiet_s: float = 0.002, max_s: float = 0.05) -> int:
        """Drop bytes until the line has been quiet for `quiet_s` (resynchronising)."""
        dropped, deadline = 0, time.monotonic() + max_s
        while time.monotonic() < deadline:
            chunk = self.read(4096, quiet_s)
            if not chunk:
                break
            dropped += len(chunk)
        return dropped

    def __enter__(self) -> Transport:
        self.open()
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


class SerialTransport(Transport):
    """A serial port through pyserial: RS-232 adapters and USB CDC-ACM ports (/dev/ttyACM0).

    CDC-ACM devices ignore the baud rate; it is set anyway for real UARTs.
    """

    def __init__(self, port: str, baudrate: int = 115200, write_timeout_s: float = 0.05):
        self.port = port
        self.name = port
        self.baudrate = baudrate
        self.write_timeout_s = write_timeout_s

    def open(self) -> None:
        import serial

        if self._handle is not None:
            return
        try:
            self._handle = serial.Serial(
                self.port, self.baudrate, timeout=0, write_timeout=self.write_timeout_s
            )
        except serial.SerialException as exc:
            raise self._open_error(exc) from None
        except (OSError, ValueError) as exc:
            raise DeviceOpenError(f"cannot open serial port {self.port}: {exc}") from None

    def _open_error(self, exc: Exception) -> DeviceOpenError:
        code = getattr(exc, "errno", None)
        if code == errno.ENOENT:
            return DeviceOpenError(
                f"no such serial port: {self.port} (is the arm plugged in? "
                "`sasprobe devices` lists the ports)"
            )
        if code in (errno.EACCES, errno.EPERM):
            return DeviceOpenError(permission_hint(self.port))
        if code == errno.EBUSY:
            return DeviceOpenError(f"serial port {self.port} is busy: another program has it open")
        return DeviceOpenError(f"cannot open serial port {self.port}: {exc}")

    def close(self) -> None:
        ser, self._handle = self._handle, None
        if ser is not None:
            try:
                ser.close()
            except Exception:  # closing a port whose device vanished may fail; it is closed anyway
                pass

    def write(self, data: bytes) -> None:
        """All of `data`, waiting at most the write timeout for room in the port's buffer.

        Written here on the port's non-blocking descriptor rather than by pyserial's
        `write`, which also raises its timeout when the bytes all went out but the writer
        was descheduled past the deadline before it looked at the clock (a busy machine):
        a port that took every byte is not lost."""
        ser = self._require()
        remaining = memoryview(data)
        deadline = time.monotonic() + self.write_timeout_s
        try:
            fd = ser.fileno()
            while remaining:
                try:
                    remaining = remaining[os.write(fd, remaining) :]
                except BlockingIOError:
                    pass
                if not remaining:
                    return
                left = deadline - time.monotonic()
                if left <= 0:
                    raise DeviceFault(
                        f"serial port {self.port} lost: it took no bytes for "
                        f"{self.write_timeout_s * 1000:.0f} ms"
                    )
                select.select([], [fd], [], left)
        except (OSError, ValueError) as exc:
            raise DeviceFault(f"serial port {self.port} lost: {exc}") from None

    def read(self, max_bytes: int, timeout_s: float) -> bytes:
        import serial

        ser = self._require()
        try:
            waiting = ser.in_waiting
            if not waiting:
                ready, _, _ = select.select([ser.fileno()], [], [], max(timeout_s, 0.0))
                if not ready:
                    return b""
                waiting = max(ser.in_waiting, 1)
            data = ser.read(min(waiting, max_bytes))
        except (serial.SerialException, OSError, ValueError) as exc:
            raise DeviceFault(f"serial port {self.port} lost: {exc}") from None
        if not data:  # readable but empty: the other end hung up
            raise DeviceFault(f"serial port {self.port} lost: hang-up")
        return data


def load_hidapi():
    """The hidapi module, or DeviceOpenError when it cannot load."""
    try:
        import hid
    except ImportError as exc:  # the hidapi wheel bundles its library; this is rare
        raise DeviceOpenError(f"hidapi is not usable: {exc} (pip install hidapi)") from None
    return hid


class HidTransport(Transport):
    """One HID device through hidapi; reads return one input report (report id first).

    The handle is set non-blocking when opened: hidapi's `read(n)` (timeout 0) is then a
    poll that returns at once, where on a blocking handle it waits for the next report
    (libusb/hidapi linux/hid.c `hid_read`; trezor/cython-hidapi hid.pyx `device.read`
    calls `hid_read` for a timeout of 0 and `hid_read_timeout` only for one above 0).

    `hid_api` is the hidapi module (`import hid`); tests pass a fake with the same surface
    (`enumerate()`, `device()`), the boundary where hardware would be.
    """

    def __init__(self, path: bytes, hid_api=None, label: str = "HID device"):
        self.path = path
        self.name = path.decode(errors="replace") if isinstance(path, bytes) else str(path)
        self.label = label
        self._api = hid_api

    @property
    def api(self):
        if self._api is None:
            self._api = load_hidapi()
        return self._api

    def open(self) -> None:
        if self._handle is not None:
            return
        dev = self.api.device()
        try:
            dev.open_path(self.path)
        except (OSError, ValueError) as exc:
            if (
                self.name.startswith("/dev/")
                and os.path.exists(self.name)
                and not os.access(self.name, os.R_OK | os.W_OK)
            ):
                raise DeviceOpenError(permission_hint(self.name, group="plugdev")) from None
            raise DeviceOpenError(
                f"cannot open {self.label} at {self.name}: {exc} "
                f"(unplugged? no permission? {UDEV_HINT})"
            ) from None
        if dev.set_nonblocking(1) == -1:
            dev.close()
            raise DeviceOpenError(
                f"cannot make reads from {self.label} at {self.name} non-blocking"
            )
        self._handle = dev

    def report_descriptor(self) -> bytes | None:
        """The device's HID report descriptor, or None where hidapi cannot give it."""
        dev = self._require()
        try:
            return bytes(dev.get_report_descriptor())
        except (AttributeError, OSError, ValueError):  # hidapi before 0.14, or a backend without it
            return None

    def close(self) -> None:
        dev, self._handle = self._handle, None
        if dev is not None:
            try:
                dev.close()
            except Exception:  # the device may already be gone
                pass

    def write(self, data: bytes) -> None:
        dev = self._require()
        try:
            n = dev.write(list(data))
        except (OSError, ValueError) as exc:
            raise DeviceFault(f"{self.label} lost: {exc}") from None
        if n is not None and n < 0:
            raise DeviceFault(f"{self.label} lost: write failed")

    def read(self, max_bytes: int, timeout_s: float) -> bytes:
        dev = self._require()
        try:
            report = dev.read(max_bytes, math.ceil(timeout_s * 1000) if timeout_s > 0 else 0)
        except (OSError, ValueError) as exc:
            raise DeviceFault(f"{self.label} lost: {exc}") from None
        return bytes(report)


class TransferTimeout(DeviceFault):
    """A USB transfer the device did not complete in time (it is still there)."""


class UsbTransport(Transport):
    """Raw USB bulk (or interrupt) endpoints through pyusb.

    `backend` is a pyusb backend; None lets pyusb find libusb. Tests pass a backend that
    implements pyusb's `IBackend` over an emulated device, so pyusb's own code runs.
    """

    def __init__(
        self,
        vendor_id: int,
        product_id: int,
        ep_out: int,
        ep_in: int,
        *,
        backend=None,
        interface: int = 0,
        label: str = "USB device",
    ):
        self.vendor_id, self.product_id = vendor_id, product_id
        self.ep_out, self.ep_in = ep_out, ep_in
        self.backend = backend
        self.interface = interface
        self.label = label
        self.name = f"the {label}"

    def open(self) -> None:
        import usb.core
        import usb.util

        if self._handle is not None:
            return
        try:
            dev = usb.core.find(
                idVendor=self.vendor_id, idProduct=self.product_id, backend=self.backend
            )
        except usb.core.NoBackendError:
            raise DeviceOpenError(
                "libusb-1.0 is not installed, so pyusb cannot reach USB devices "
                "(Debian/Ubuntu: sudo apt install libusb-1.0-0)"
            ) from None
        if dev is None:
            raise DeviceOpenError(
                f"no {self.label} found (USB {self.vendor_id:04x}:{self.product_id:04x}): "
                "is it plugged in and powered?"
            )
        try:
            try:
                if dev.is_kernel_driver_active(self.interface):
                    dev.detach_kernel_driver(self.interface)
            except NotImplementedError:  # not every platform/backend has kernel drivers
                pass
            dev.set_configuration()
            usb.util.claim_interface(dev, self.interface)
        except usb.core.USBError as exc:
            usb.util.dispose_resources(dev)
            if exc.errno in (errno.EACCES, errno.EPERM):
                where = f"the {self.label} (USB {self.vendor_id:04x}:{self.product_id:04x})"
                raise DeviceOpenError(permission_hint(where, group="plugdev")) from None
            if exc.errno == errno.EBUSY:
                raise DeviceOpenError(
                    f"the {self.label} is busy: another program has it open"
                ) from None
            raise DeviceOpenError(f"cannot open the {self.label}: {exc}") from None
        self._handle = dev

    def close(self) -> None:
        import usb.util

        dev, self._handle = self._handle, None
        if dev is not None:
            try:
                usb.util.dispose_resources(dev)
            except Exception:  # a vanished device cannot release its interface; it is gone anyway
                pass

    def control(
        self,
        request_type: int,
        request: int,
        value: int = 0,
        index: int = 0,
        data_or_length=None,
        timeout_s: float = 0.1,
    ):
        import usb.core

        dev = self._require()
        try:
            return dev.ctrl_transfer(
                request_type, request, value, index, data_or_length, int(timeout_s * 1000)
            )
        except usb.core.USBError as exc:
            raise DeviceFault(f"the {self.label} lost: {exc}") from None

    def write(self, data: bytes, timeout_s: float = 0.1) -> None:
        import usb.core

        dev = self._require()
        try:
            n = dev.write(self.ep_out, data, max(int(timeout_s * 1000), 1))
        except usb.core.USBTimeoutError:
            raise TransferTimeout(
                f"the {self.label} took no data for {timeout_s * 1000:.0f} ms"
            ) from None
        except usb.core.USBError as exc:
            if exc.errno == errno.ETIMEDOUT:
                raise TransferTimeout(
                    f"the {self.label} took no data for {timeout_s * 1000:.0f} ms"
                ) from None
            raise DeviceFault(f"the {self.label} lost: {exc}") from None
        if n != len(data):
            raise DeviceFault(f"the {self.label}: short write ({n} of {len(data)} bytes)")

    def read(self, max_bytes: int, timeout_s: float) -> bytes:
        import usb.core

        dev = self._require()
        try:
            return bytes(dev.read(self.ep_in, max_bytes, max(int(timeout_s * 1000), 1)))
        except usb.core.USBTimeoutError:
            return b""
        except usb.core.USBError as exc:
            if exc.errno == errno.ETIMEDOUT:
                return b""
            raise DeviceFault(f"the {self.label} lost: {exc}") from None
