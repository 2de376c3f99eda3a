"""An emulated Novint Falcon behind pyusb's backend interface (`IBackend`), so the driver
goes through pyusb's own find, configuration, claiming and transfers. The device side
is `falcon_device`; USB ids and endpoints are libnifalcon's (FalconComm.h,
FalconCommLibUSB.cpp). Nothing here comes from sasprobe.

`EmulatedUsbBackend(FalconHardware(image))` is the in-process form. `launch()` runs the
hardware in this process behind a socket, for a driver in another process (the daemon).
"""

from __future__ import annotations

import array
import errno
import os
import tempfile
import threading
from dataclasses import dataclass, field
from multiprocessing.connection import Client, Listener

import usb.backend
import usb.core

from tests.emulators.falcon_device import FalconHardware, Hand

VENDOR_ID, PRODUCT_ID, EP_OUT, EP_IN = 0x0403, 0xCB48, 0x02, 0x81


@dataclass
class _Descriptor:
    fields: dict = field(default_factory=dict)

    def __getattr__(self, name):
        try:
            return self.__dict__["fields"][name]
        except KeyError:
            raise AttributeError(name) from None


class EmulatedUsbBackend(usb.backend.IBackend):
    """pyusb's backend interface over one FalconHardware (or its remote proxy)."""

    def __init__(self, hardware):
        super().__init__()
        self.hw = hardware
        self.access_denied = False  # as libusb answers without a udev rule

    def enumerate_devices(self):
        if self.hw.plugged:
            yield 0

    def get_device_descriptor(self, dev):
        return _Descriptor(
            dict(
                bLength=18,
                bDescriptorType=1,
                bcdUSB=0x0200,
                bDeviceClass=0,
                bDeviceSubClass=0,
                bDeviceProtocol=0,
                bMaxPacketSize0=8,
                idVendor=VENDOR_ID,
                idProduct=PRODUCT_ID,
                bcdDevice=0x0400,
                iManufacturer=0,
                iProduct=0,
                iSerialNumber=0,
                bNumConfigurations=1,
                address=5,
                bus=1,
                port_number=2,
                port_numbers=(2,),
                speed=2,
            )
        )

    def get_configuration_descriptor(self, dev, config):
        return _Descriptor(
            dict(
                bLength=9,
                bDescriptorType=2,
                wTotalLength=32,
                bNumInterfaces=1,
                bConfigurationValue=1,
                iConfiguration=0,
                bmAttributes=0x80,
                bMaxPower=50,
                extra_descriptors=[],
            )
        )

    def get_interface_descriptor(self, dev, intf, alt, config):
        return _Descriptor(
            dict(
                bLength=9,
                bDescriptorType=4,
                bInterfaceNumber=0,
                bAlternateSetting=0,
                bNumEndpoints=2,
                bInterfaceClass=0xFF,
                bInterfaceSubClass=0xFF,
                bInterfaceProtocol=0xFF,
                iInterface=0,
                extra_descriptors=[],
            )
        )

    def get_endpoint_descriptor(self, dev, ep, intf, alt, config):
        return _Descriptor(
            dict(
                bLength=7,
                bDescriptorType=5,
                bEndpointAddress=(EP_IN, EP_OUT)[ep],
                bmAttributes=0x02,
                wMaxPacketSize=64,
                bInterval=0,
                bRefresh=0,
                bSynchAddress=0,
                extra_descriptors=[],
            )
        )

    def open_device(self, dev):
        generation = self.hw.generation
        self.hw.check(generation)
        if self.access_denied:
            raise usb.core.USBError("Access denied (insufficient permissions)", errno=errno.EACCES)
        return generation

    def close_device(self, dev_handle):
        pass

    def set_configuration(self, dev_handle, config_value):
        self.hw.check(dev_handle)

    def get_configuration(self, dev_handle):
        self.hw.check(dev_handle)
        return 1

    def claim_interface(self, dev_handle, intf):
        self.hw.check(dev_handle)

    def release_interface(self, dev_handle, intf):
        self.hw.check(dev_handle)

    def is_kernel_driver_active(self, dev_handle, intf):
        return False

    def ctrl_transfer(self, dev_handle, bmRequestType, bRequest, wValue, wIndex, data, timeout):
        if bmRequestType != 0x40:
            raise usb.core.USBError("Pipe error", errno=errno.EPIPE)
        self.hw.control(dev_handle, bRequest, wValue, wIndex)
        return 0

    def bulk_write(self, dev_handle, ep, intf, data, timeout):
        self.hw.host_write(dev_handle, bytes(data))
        return len(data)

    def bulk_read(self, dev_handle, ep, intf, buff, timeout):
        data = self.hw.host_read(dev_handle, len(buff), timeout)
        buff[: len(data)] = array.array("B", data)
        return len(data)


# -- a Falcon for a driver in another process ---------------------------------------------

AUTHKEY = b"falcon-emulator"
CALL_TIMEOUT_S = 10.0  # longest a call from the driver's process waits for the emulator
REMOTE_CALLS = {"check", "control", "host_write", "host_read", "plugged", "generation"}


def _serve_connection(hardware: FalconHardware, conn) -> None:
    with conn:
        while True:
            try:
                name, args = conn.recv()
            except (EOFError, OSError):
                return
            try:
                value = getattr(hardware, name) if name in REMOTE_CALLS else None
                conn.send(("ok", value(*args) if callable(value) else value))
            except usb.core.USBError as exc:
                conn.send(("usb", (exc.strerror, exc.errno)))


class RemoteHardware:
    """Stands in for FalconHardware in the driver's process: every call goes over the socket."""

    def __init__(self, address: str):
        self.address = address
        self._local = threading.local()  # one connection per thread: reader and writer block apart

    def _call(self, name, *args):
        conn = getattr(self._local, "conn", None)
        if conn is None:
            conn = self._local.conn = Client(self.address, family="AF_UNIX", authkey=AUTHKEY)
        conn.send((name, args))
        if not conn.poll(CALL_TIMEOUT_S):  # the test process went away: fail as a USB timeout
            conn.close()
            self._local.conn = None
            raise usb.core.USBError("Operation timed out", errno=errno.ETIMEDOUT)
        kind, value = conn.recv()
        if kind == "usb":
            raise usb.core.USBError(value[0], errno=value[1])
        return value

    plugged = property(lambda self: self._call("plugged"))
    generation = property(lambda self: self._call("generation"))

    def check(self, *args):
        return self._call("check", *args)

    def control(self, *args):
        return self._call("control", *args)

    def host_write(self, *args):
        return self._call("host_write", *args)

    def host_read(self, *args):
        return self._call("host_read", *args)


class LaunchedFalcon:
    """An emulated Falcon served to another process: `device_spec`, `env`, `hand`, `close()`."""

    def __init__(self, image_size: int = 1500, hand_target=(0.0, 0.0, 0.0), **options):
        self.folder = tempfile.TemporaryDirectory(prefix="falcon-emu")
        firmware = os.path.join(self.folder.name, "falcon.bin")
        image = os.urandom(image_size)
        with open(firmware, "wb") as f:
            f.write(image)
        self.hand = Hand(hand_target)
        self.hardware = FalconHardware(image, hand=self.hand, **options)
        self.hand.hardware = self.hardware
        address = os.path.join(self.folder.name, "usb")
        self._listener = Listener(address, family="AF_UNIX", authkey=AUTHKEY)
        threading.Thread(target=self._accept, daemon=True).start()
        self.device_spec = f"falcon:{firmware}"
        self.env = {
            "SASPROBE_USB_BACKEND": "tests.emulators.falcon_usb:backend_from_environment",
            "SASPROBE_FALCON_EMU_SOCKET": address,
        }

    def _accept(self) -> None:
        while True:
            try:
                conn = self._listener.accept()
            except OSError:  # closed
                return
            threading.Thread(
                target=_serve_connection, args=(self.hardware, conn), daemon=True
            ).start()

    def close(self) -> None:
        self._listener.close()
        self.folder.cleanup()


def launch(**options) -> LaunchedFalcon:
    """A Falcon for a driver in a subprocess. Options: image_size, hand_target and those of
    FalconHardware (hand_stiffness_n_per_mm, probes_ignored, macos, loader_silent, ...)."""
    return LaunchedFalcon(**options)


def backend_from_environment():
    """SASPROBE_USB_BACKEND factory: the launched Falcon (SASPROBE_FALCON_EMU_SOCKET), or a
    local one accepting the image in SASPROBE_FALCON_EMU_FIRMWARE, homed by a user who
    sweeps it while the LED is red (SASPROBE_FALCON_EMU_UNPLUGGED=1: none attached)."""
    if os.environ.get("SASPROBE_FALCON_EMU_SOCKET"):
        return EmulatedUsbBackend(RemoteHardware(os.environ["SASPROBE_FALCON_EMU_SOCKET"]))
    with open(os.environ["SASPROBE_FALCON_EMU_FIRMWARE"], "rb") as f:
        image = f.read()
    hand = Hand()
    hardware = FalconHardware(image, hand=hand)
    hand.hardware = hardware
    if os.environ.get("SASPROBE_FALCON_EMU_UNPLUGGED") == "1":
        hardware.unplug()
    return EmulatedUsbBackend(hardware)
