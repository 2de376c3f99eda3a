"""An emulated Novint Falcon behind a pyusb backend.

`FalconHardware` is the device side: the FTDI bridge's SIO requests and status bytes,
the firmware loader (handshake at 9600 baud, then 128-byte blocks echoed at divisor
0x15), and, once the right image is loaded and the host switches to normal mode, the
16-byte nibble frames with encoders, buttons, homing and motor commands driving a held
stylus. `EmulatedUsbBackend` implements pyusb's `IBackend` over it, so the driver goes
through pyusb's own `core.find`, configuration, interface claiming and transfers.

Pulling the cable (`unplug()`) makes every transfer raise USBError(ENODEV) and the device
vanish from enumeration; `replug()` brings back a freshly powered Falcon: loader mode,
no firmware, not homed.
"""

from __future__ import annotations

import array
import errno
import json
import os
import threading
import time
from dataclasses import dataclass, field

import numpy as np
import usb.backend
import usb.core

from sasprobe.devices import falcon as F
from sasprobe.devices.ftdi import (DIVISOR_9600, PURGE_RX, PURGE_TX, SIO_MODEM_CTRL, SIO_RESET, SIO_SET_BAUD_RATE,
                                   SIO_SET_LATENCY_TIMER, STATUS_BYTES)
from sasprobe.devices.kinematics import DeltaArm, tip_force
from tests.emulators.physics import HeldStylus

MODEM_STATUS = b"\x01\x60"  # FTDI status bytes: CTS/DSR idle, transmitter empty


class FalconHardware:
    def __init__(self, firmware: bytes, *, hand=None, start_mm=(0.0, 0.0, 0.0), corrupt_echo_attempts=()):
        self.expected_firmware = bytes(firmware)
        self.kinematics = DeltaArm()
        self.hand = hand
        self.start_mm = start_mm
        self.corrupt_echo_attempts = set(corrupt_echo_attempts)
        self.lock = threading.RLock()
        self._plugged = True
        self.cable_schedule = None  # (seconds after the first boot to unplug, seconds to stay out)
        self.first_boot = None
        self._schedule_done = 0
        self.generation = 0
        self.buttons = 0
        self.host_bad_frames = 0
        self.inject_before_reply: list[bytes] = []  # raw bytes sent ahead of the next reply
        self.frames_answered = 0
        self.max_command_force_n = 0.0
        self.last_motor = [0, 0, 0]
        self.last_force_n = np.zeros(3)
        self.upload_attempts = 0
        self._power_on()

    # -- power ------------------------------------------------------------------------
    def _power_on(self) -> None:
        self.running = False
        self.loader_state = "idle"
        self.loaded = bytearray()
        self.latency_ms = 16
        self.divisor = DIVISOR_9600
        self.dtr = self.rts = False
        self.host_in = bytearray()
        self.out = bytearray()
        self.homing = False
        self.homed = [False, False, False]
        self.flags = 0
        self.motor = [0, 0, 0]
        self.stylus = HeldStylus(self.start_mm, hand=self.hand, mass_kg=0.15)
        self.count_offset = self._true_counts()  # relative encoders: zero at power-on
        self._last_absolute = self.count_offset.copy()
        self._echoed = 0

    @property
    def plugged(self) -> bool:
        self._follow_cable_schedule()
        return self._plugged

    def unplug(self) -> None:
        with self.lock:
            self._plugged = False
            self.generation += 1

    def replug(self) -> None:
        with self.lock:
            self._power_on()
            self._plugged = True

    def _follow_cable_schedule(self) -> None:
        if self.cable_schedule is None or self.first_boot is None or self._schedule_done == 2:
            return
        elapsed = time.monotonic() - self.first_boot
        after, out_for = self.cable_schedule
        if self._schedule_done == 0 and elapsed >= after:
            self._schedule_done = 1
            self.unplug()
        elif self._schedule_done == 1 and elapsed >= after + out_for:
            self._schedule_done = 2
            self.replug()

    # -- kinematics ---------------------------------------------------------------------
    def _true_angles(self) -> np.ndarray:
        return self.kinematics.inverse(self.stylus.position)

    def _true_counts(self) -> np.ndarray:
        return F.angles_to_counts(self._true_angles())

    def motor_force(self, motor=None) -> np.ndarray:
        """The tip force the motors produce at the current pose (N)."""
        theta = self._true_angles()
        torques = F.motor_to_torques(self.motor if motor is None else motor)
        return tip_force(self.kinematics.jacobian(theta, self.stylus.position), torques)

    # -- FTDI control requests --------------------------------------------------------
    def control(self, request: int, value: int, index: int) -> None:
        with self.lock:
            if request == SIO_RESET and value in (PURGE_RX, PURGE_TX):
                if value == PURGE_RX:
                    self.host_in.clear()
                else:
                    self.out.clear()
            elif request == SIO_SET_LATENCY_TIMER:
                self.latency_ms = value & 0xFF
            elif request == SIO_SET_BAUD_RATE:
                self.divisor = value | (index << 16)
                self._baud_changed()
            elif request == SIO_MODEM_CTRL:
                if value & 0x0100:
                    was = self.dtr
                    self.dtr = bool(value & 0x01)
                    if self.dtr and not was and not self.running:  # DTR edge resets the loader
                        self.loader_state = "reset"
                        self.loaded.clear()
                if value & 0x0200:
                    self.rts = bool(value & 0x02)

    def _baud_changed(self) -> None:
        if self.running:
            return
        if self.divisor == F.NORMAL_DIVISOR and self.loader_state == "loading":
            if bytes(self.loaded) == self.expected_firmware:
                self.running = True  # the firmware starts; its encoders count from zero
                self.first_boot = self.first_boot or time.monotonic()
                self.count_offset = self._true_counts()
                self._last_absolute = self.count_offset.copy()
            self.loader_state = "idle"
        elif self.divisor == F.LOADER_DIVISOR and self.loader_state == "probed":
            self.loader_state = "handshake"

    # -- bulk OUT ---------------------------------------------------------------------
    def host_write(self, data: bytes) -> None:
        with self.lock:
            if not self.running:
                self._loader_bytes(bytes(data))
                return
            self.host_in += data
            while len(self.host_in) >= F.FRAME_SIZE:
                chunk = bytes(self.host_in[:F.FRAME_SIZE])
                del self.host_in[:F.FRAME_SIZE]
                self._frame(chunk)

    def _loader_bytes(self, data: bytes) -> None:
        if self.loader_state == "reset" and self.divisor == DIVISOR_9600 and data == F.LOADER_PROBE:
            self.out += F.LOADER_REPLY
            self.loader_state = "probed"
        elif self.loader_state == "handshake" and data == F.LOADER_HANDSHAKE:
            self.out += data
            self.loader_state = "loading"
            self.upload_attempts += 1
            self._echoed = 0
        elif self.loader_state == "loading":
            self.loaded += data
            echo = bytearray(data)
            if self.upload_attempts in self.corrupt_echo_attempts and self._echoed == 0:
                echo[0] ^= 0xFF  # a flaky link: one bad echo byte
            self._echoed += 1
            self.out += echo
        # anything else (frames sent to a loader, wrong baud) is ignored, as a loader would

    def _frame(self, chunk: bytes) -> None:
        try:
            motor, flags = F.decode_frame(chunk)
        except F.FrameError:
            self.host_bad_frames += 1
            return
        self.motor, self.flags = motor, flags
        self.last_motor = motor
        self.homing = bool(flags & F.HOMING_MODE)
        force = self.motor_force()
        self.last_force_n = force  # what the motors produce at the pose the frame arrived in
        self.max_command_force_n = max(self.max_command_force_n, float(np.linalg.norm(force)))
        self.stylus.advance(force)
        absolute = self._true_counts()
        if self.homing:  # passing the index mark (absolute count 0, thigh at 35°) homes an axis
            for i in range(3):
                if not self.homed[i] and np.sign(absolute[i]) != np.sign(self._last_absolute[i]):
                    self.homed[i] = True
                    self.count_offset[i] = 0
        self._last_absolute = absolute
        counts = absolute - self.count_offset
        status = (self.buttons & 0xF) | (sum(1 << i for i in range(3) if self.homed[i]) << F.HOMED_SHIFT)
        for junk in self.inject_before_reply:
            self.out += junk
        self.inject_before_reply = []
        self.out += F.encode_frame([int(c) for c in counts], status)
        self.frames_answered += 1

    # -- bulk IN ----------------------------------------------------------------------
    def host_read(self, size: int, timeout_ms: int) -> bytes:
        packet = self._packet(size)
        if packet is None:
            # nothing queued: the chip answers with a status-only packet when its latency
            # timer (or the host's timeout) expires
            time.sleep(min(max(self.latency_ms, 1), max(timeout_ms, 1)) / 1000.0)
            packet = self._packet(size)
        return packet if packet is not None else MODEM_STATUS

    def _packet(self, size: int) -> bytes | None:
        plugged = self.plugged
        with self.lock:
            if not plugged:
                raise usb.core.USBError("No such device", errno=errno.ENODEV)
            if not self.out:
                return None
            n = min(size - STATUS_BYTES, len(self.out))
            data = bytes(self.out[:n])
            del self.out[:n]
            return MODEM_STATUS + data


@dataclass
class _Descriptor:
    fields: dict = field(default_factory=dict)

    def __getattr__(self, name):
        try:
            return self.__dict__["fields"][name]
        except KeyError:
            raise AttributeError(name) from None


class EmulatedUsbBackend(usb.backend.IBackend):
    """pyusb's backend interface over one FalconHardware."""

    def __init__(self, hardware: FalconHardware):
        super().__init__()
        self.hw = hardware
        self.open_handles = 0
        self.access_denied = False  # as libusb answers without a udev rule
        self.report_path = None  # write_report() here on every close

    def enumerate_devices(self):
        if self.hw.plugged:
            yield self.hw

    def get_device_descriptor(self, dev):
        return _Descriptor(dict(
            bLength=18, bDescriptorType=1, bcdUSB=0x0200, bDeviceClass=0, bDeviceSubClass=0, bDeviceProtocol=0,
            bMaxPacketSize0=8, idVendor=F.VENDOR_ID, idProduct=F.PRODUCT_ID, bcdDevice=0x0400, iManufacturer=0,
            iProduct=0, iSerialNumber=0, bNumConfigurations=1, address=5, bus=1, port_number=2, port_numbers=(2,),
            speed=2))

    def get_configuration_descriptor(self, dev, config):
        return _Descriptor(dict(bLength=9, bDescriptorType=2, wTotalLength=32, bNumInterfaces=1,
                                bConfigurationValue=1, iConfiguration=0, bmAttributes=0x80, bMaxPower=50,
                                extra_descriptors=[]))

    def get_interface_descriptor(self, dev, intf, alt, config):
        return _Descriptor(dict(bLength=9, bDescriptorType=4, bInterfaceNumber=0, bAlternateSetting=0,
                                bNumEndpoints=2, bInterfaceClass=0xFF, bInterfaceSubClass=0xFF,
                                bInterfaceProtocol=0xFF, iInterface=0, extra_descriptors=[]))

    def get_endpoint_descriptor(self, dev, ep, intf, alt, config):
        address = (F.EP_IN, F.EP_OUT)[ep]
        return _Descriptor(dict(bLength=7, bDescriptorType=5, bEndpointAddress=address, bmAttributes=0x02,
                                wMaxPacketSize=64, bInterval=0, bRefresh=0, bSynchAddress=0, extra_descriptors=[]))

    def _check(self, handle):
        if not self.hw.plugged or handle["generation"] != self.hw.generation:
            raise usb.core.USBError("No such device", errno=errno.ENODEV)

    def open_device(self, dev):
        if not self.hw.plugged:
            raise usb.core.USBError("No such device", errno=errno.ENODEV)
        if self.access_denied:
            raise usb.core.USBError("Access denied (insufficient permissions)", errno=errno.EACCES)
        self.open_handles += 1
        return {"generation": self.hw.generation}

    def close_device(self, dev_handle):
        self.open_handles -= 1
        if self.report_path:
            self.write_report()

    def write_report(self) -> None:
        """What the device saw, for tests whose driver runs in another process (the daemon)."""
        hw = self.hw
        report = {"frames_answered": hw.frames_answered, "max_force_n": hw.max_command_force_n,
                  "last_motor": list(hw.last_motor), "homed": list(hw.homed), "running": hw.running,
                  "upload_attempts": hw.upload_attempts, "generation": hw.generation}
        with open(self.report_path, "w") as f:
            json.dump(report, f)

    def set_configuration(self, dev_handle, config_value):
        self._check(dev_handle)

    def get_configuration(self, dev_handle):
        self._check(dev_handle)
        return 1

    def claim_interface(self, dev_handle, intf):
        self._check(dev_handle)

    def release_interface(self, dev_handle, intf):
        self._check(dev_handle)

    def is_kernel_driver_active(self, dev_handle, intf):
        return False

    def ctrl_transfer(self, dev_handle, bmRequestType, bRequest, wValue, wIndex, data, timeout):
        self._check(dev_handle)
        if bmRequestType != 0x40:
            raise usb.core.USBError("Pipe error", errno=errno.EPIPE)
        self.hw.control(bRequest, wValue, wIndex)
        return 0

    def bulk_write(self, dev_handle, ep, intf, data, timeout):
        self._check(dev_handle)
        if ep != F.EP_OUT:
            raise usb.core.USBError("Pipe error", errno=errno.EPIPE)
        self.hw.host_write(bytes(data))
        return len(data)

    def bulk_read(self, dev_handle, ep, intf, buff, timeout):
        self._check(dev_handle)
        if ep != F.EP_IN:
            raise usb.core.USBError("Pipe error", errno=errno.EPIPE)
        data = self.hw.host_read(len(buff), timeout)
        buff[:len(data)] = array.array("B", data)
        return len(data)


def backend_from_environment():
    """Factory for SASPROBE_USB_BACKEND in subprocess tests (the CLI, the daemon).

    SASPROBE_FALCON_EMU_FIRMWARE names the image the emulated loader accepts. The user's
    hand homes the Falcon whenever its LED is red (sweeping the grip through the index
    marks), and otherwise holds it at `SASPROBE_FALCON_EMU_HOLD` ("x,y,z" mm, default the
    centre). SASPROBE_FALCON_EMU_UNPLUGGED=1 starts with no Falcon attached;
    SASPROBE_FALCON_EMU_PULL="AFTER,FOR" pulls the cable AFTER seconds from the first
    boot for FOR seconds; SASPROBE_FALCON_EMU_REPORT names a JSON file the emulator
    writes what it saw into whenever the driver closes it.
    """
    with open(os.environ["SASPROBE_FALCON_EMU_FIRMWARE"], "rb") as f:
        firmware = f.read()
    hold = tuple(float(v) for v in os.environ.get("SASPROBE_FALCON_EMU_HOLD", "0,0,0").split(","))
    hand = LedWatchingHand(hold)
    hardware = FalconHardware(firmware, hand=hand)
    hand.hardware = hardware
    if os.environ.get("SASPROBE_FALCON_EMU_UNPLUGGED") == "1":
        hardware.unplug()
    if os.environ.get("SASPROBE_FALCON_EMU_PULL"):
        after, out_for = (float(v) for v in os.environ["SASPROBE_FALCON_EMU_PULL"].split(","))
        hardware.cable_schedule = (after, out_for)
    backend = EmulatedUsbBackend(hardware)
    backend.report_path = os.environ.get("SASPROBE_FALCON_EMU_REPORT")
    return backend


class LedWatchingHand:
    """A user who homes the Falcon while its LED is red, then holds the grip still."""

    def __init__(self, hold=(0.0, 0.0, 0.0)):
        self.hold = hold
        self.hardware: FalconHardware | None = None

    def __call__(self, t: float):
        if self.hardware is not None and self.hardware.flags & F.LED_RED:
            return (0.0, 0.0, 35.0 * np.sin(np.pi * t) ** 2)  # every thigh passes its index at 35°
        return self.hold
