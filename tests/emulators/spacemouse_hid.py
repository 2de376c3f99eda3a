"""Emulated 3Dconnexion devices on emulated hidraw nodes (the device side of `hidapi_fake`).

What each product is and how it reports, written from spacenavd (FreeSpacenav/spacenavd,
commit bac572ae) and libspnav (FreeSpacenav/libspnav, commit bcc2e295):
- the products: spacenavd src/dev.c `usbdb` (6-DoF devices) and `devid_blacklist`
  (CadMice, keyboards, numpads: same vendor, other HID collections);
- the axes: src/dev.c says newer USB devices use axis 1 as forward/back and axis 2 as
  up/down, the old serial devices (and the models listed without DF_SWAPYZ) the other
  way round; spacenavd's common order is left-handed with z away from the user
  (libspnav src/util.c negates z to move an OpenGL object). So a newer cap reports
  x = pushed right, y = pulled toward the user, z = pushed down; an older one
  x = right, y = lifted, z = pushed away. Twists follow the same axes.
- the reports: src/dev_usb_freebsd.c `read_hid`: report 1 with 16-bit axes (three, or
  all six in 12 bytes), report 2 with the three rotations, report 3 the buttons, 23 the
  battery. Which models send the 12-byte form is not in the sources; this emulator
  sends it for 3Dconnexion-vendor products and reports 1 + 2 for the Logitech-era ones.
- the buttons: spacenavd's bnhack tables name keys by evdev code, and the Linux HID
  layer gives button usage n the code 0x100 + n - 1 (drivers/hid/hid-input.c), so a key
  of code c is bit c - 0x100 of report 3.
- reports on change only: a cap held still sends nothing (spacenavd's example
  spnavrc, `repeat-interval`).
The report descriptor is built from the USB HID 1.11 item encoding (§6.2.2).

`launch(**options)` plugs one device into a bus and returns it with `device_spec`,
`env` (what a daemon subprocess needs to reach the bus), `hand` (the user's hand on
the cap), `close()`.
"""

from __future__ import annotations

import struct
from dataclasses import dataclass, field
from pathlib import Path

from tests.emulators.hidapi_fake import BUS_ENV, HidBus, HidNode

REPO_ROOT = Path(__file__).resolve().parents[2]
HID_API_FACTORY = "tests.emulators.hidapi_fake:module_from_environment"

PLAIN_KEYS = {"left": 0x100, "right": 0x101}
PRO_KEYS = {
    "menu": 256,
    "fit": 257,
    "T": 258,
    "R": 260,
    "F": 261,
    "rotate": 264,
    "1": 268,
    "2": 269,
    "3": 270,
    "4": 271,
    "esc": 278,
    "alt": 279,
    "shift": 280,
    "ctrl": 281,
    "lock": 282,
}
ENTERPRISE_KEYS = {
    **PRO_KEYS,
    "iso": 266,
    "5": 272,
    "6": 273,
    "7": 274,
    "8": 275,
    "9": 276,
    "10": 277,
    "enter": 291,
    "delete": 292,
    "11": 332,
    "12": 333,
    "V1": 358,
    "V2": 359,
    "V3": 360,
    "tab": 430,
    "space": 431,
}

DESKTOP, MULTI_AXIS, MOUSE, KEYBOARD = 0x01, 0x08, 0x02, 0x06


@dataclass(frozen=True)
class Product:
    name: str
    vendor_id: int
    product_id: int
    y_toward_user: bool = True  # the newer axis layout (False: y lifted, z pushed away)
    keys: dict = field(default_factory=lambda: dict(PLAIN_KEYS))  # label → evdev code
    usage: int = MULTI_AXIS  # the HID application collection (a CadMouse is a mouse)

    @property
    def combined_report(self) -> bool:
        return self.vendor_id == 0x256F

    @property
    def button_count(self) -> int:
        """Button usages declared: enough for the highest key (two on the plain models)."""
        highest = max(self.keys.values()) - 0x100 + 1
        return highest if highest <= 2 else -(-highest // 8) * 8


_L, _C = 0x046D, 0x256F
PRODUCTS = [
    Product("SpaceMouse Plus XT", _L, 0xC603, y_toward_user=False),
    Product("CADman", _L, 0xC605),
    Product("SpaceMouse Classic", _L, 0xC606, y_toward_user=False),
    Product("Spaceball 5000", _L, 0xC621),
    Product("SpaceTraveler", _L, 0xC623),
    Product("SpacePilot", _L, 0xC625),
    Product("SpaceNavigator", _L, 0xC626),
    Product("SpaceExplorer", _L, 0xC627),
    Product("SpaceNavigator for Notebooks", _L, 0xC628),
    Product("SpacePilot Pro", _L, 0xC629),
    Product("SpaceMouse Pro", _L, 0xC62B, keys=PRO_KEYS),
    Product("NuLOOQ", _L, 0xC640, y_toward_user=False),
    Product("SpaceMouse Wireless (cable)", _C, 0xC62E),
    Product("SpaceMouse Wireless (receiver)", _C, 0xC62F),
    Product("SpaceMouse Pro Wireless (cable)", _C, 0xC631, keys=PRO_KEYS),
    Product("SpaceMouse Pro Wireless (receiver)", _C, 0xC632, keys=PRO_KEYS),
    Product("SpaceMouse Enterprise", _C, 0xC633, keys=ENTERPRISE_KEYS),
    Product("SpaceMouse Compact", _C, 0xC635),
    Product("SpaceMouse Module", _C, 0xC636),
    Product("SpaceMouse Pro Wireless BT (USB)", _C, 0xC638, keys=PRO_KEYS),
    Product("SpaceMouse Wireless (Bluetooth)", _C, 0xC63A),
    # the universal receiver, with what is paired behind it
    Product("Universal Receiver + SpaceMouse Wireless", _C, 0xC652),
    Product("Universal Receiver + SpaceMouse Pro Wireless", _C, 0xC652, keys=PRO_KEYS),
    Product("Universal Receiver Mouse", _C, 0xC652, usage=MOUSE),  # a CadMouse on the same receiver
    # spacenavd's blacklist: same vendor, not 6-DoF
    Product("CadMouse", _C, 0xC650, usage=MOUSE),
    Product("CadMouse Pro", _C, 0xC656, usage=MOUSE),
    Product("Keyboard Pro", _C, 0xC664, usage=KEYBOARD),
    Product("Numpad Pro", _C, 0xC665, usage=KEYBOARD),
]
BY_NAME = {p.name: p for p in PRODUCTS}
SIX_DOF = [p for p in PRODUCTS if p.usage == MULTI_AXIS]


def _item(kind: int, tag: int, value: int, size: int | None = None) -> bytes:
    """One short item: prefix (tag, type, size code) and little-endian data."""
    if size is None:
        size = 1 if -128 <= value <= 255 else 2 if -32768 <= value <= 65535 else 4
    code = {0: 0, 1: 1, 2: 2, 4: 3}[size]
    data = value.to_bytes(size, "little", signed=value < 0) if size else b""
    return bytes([tag << 4 | kind << 2 | code]) + data


def _main(tag, value):
    return _item(0, tag, value)


def _global(tag, value):
    return _item(1, tag, value)


def _local(tag, value):
    return _item(2, tag, value)


USAGE_PAGE, LOGICAL_MIN, LOGICAL_MAX, REPORT_SIZE, REPORT_ID, REPORT_COUNT = (
    0x0,
    0x1,
    0x2,
    0x7,
    0x8,
    0x9,
)
USAGE, USAGE_MIN, USAGE_MAX = 0x0, 0x1, 0x2
INPUT, COLLECTION, END_COLLECTION = 0x8, 0xA, 0xC
INPUT_DATA_VAR, INPUT_CONSTANT = 0x02, 0x01


def report_descriptor(product: Product, full_scale: int) -> bytes:
    """A descriptor for the product's reports (HID 1.11 §6.2.2), as such a device would declare."""

    def axes(report_id, first_usage, count):
        out = (
            _global(REPORT_ID, report_id)
            + _global(LOGICAL_MIN, -full_scale)
            + _global(LOGICAL_MAX, full_scale)
        )
        out += b"".join(_local(USAGE, first_usage + k) for k in range(count))
        return (
            out
            + _global(REPORT_SIZE, 16)
            + _global(REPORT_COUNT, count)
            + _main(INPUT, INPUT_DATA_VAR)
        )

    d = _global(USAGE_PAGE, DESKTOP) + _local(USAGE, product.usage) + _main(COLLECTION, 0x01)
    if product.usage == MULTI_AXIS:
        d += axes(1, 0x30, 6) if product.combined_report else axes(1, 0x30, 3) + axes(2, 0x33, 3)
        n = product.button_count
        d += (
            _global(REPORT_ID, 3)
            + _global(USAGE_PAGE, 0x09)
            + _local(USAGE_MIN, 1)
            + _local(USAGE_MAX, n)
            + _global(LOGICAL_MIN, 0)
            + _global(LOGICAL_MAX, 1)
            + _global(REPORT_SIZE, 1)
            + _global(REPORT_COUNT, n)
            + _main(INPUT, INPUT_DATA_VAR)
        )
        if n % 8:
            d += _global(REPORT_COUNT, 8 - n % 8) + _main(INPUT, INPUT_CONSTANT)
    else:  # a mouse or keyboard collection: buttons and relative axes, no 6-DoF
        d += (
            _global(USAGE_PAGE, 0x09)
            + _local(USAGE_MIN, 1)
            + _local(USAGE_MAX, 3)
            + _global(REPORT_SIZE, 1)
            + _global(REPORT_COUNT, 8)
            + _main(INPUT, INPUT_DATA_VAR)
        )
    return d + _item(0, END_COLLECTION, 0, size=0)


class CapHand:
    """The user's hand on the cap: deflections are fractions of full travel in the user's frame
    (right, up, toward the user; twists about those axes, right-handed)."""

    def __init__(self, device: EmulatedSpaceMouse):
        self._device = device

    def deflect(self, translation=(0.0, 0.0, 0.0), rotation=(0.0, 0.0, 0.0)) -> None:
        self._device.set_cap(translation, rotation)

    def release(self) -> None:
        self.deflect()

    def press(self, *keys) -> None:
        self._device.set_keys(keys)


class EmulatedSpaceMouse:
    def __init__(
        self,
        product: Product | str = "SpaceMouse Compact",
        *,
        path: bytes = b"/dev/hidraw0",
        bus: HidBus | None = None,
        full_scale: int = 350,
        serial: str = "",
    ):
        self.product = BY_NAME[product] if isinstance(product, str) else product
        self._own_bus = bus is None
        self.bus = bus or HidBus()
        self.path = path
        self.full_scale = full_scale
        self._axes = [0] * 6
        self._bits = 0
        self.hand = CapHand(self)
        p = self.product
        entry = {
            "vendor_id": p.vendor_id,
            "product_id": p.product_id,
            "serial_number": serial,
            "release_number": 0x0100,
            "manufacturer_string": "3Dconnexion" if p.vendor_id == _C else "Logitech",
            "product_string": p.name,
            "usage_page": DESKTOP,
            "usage": p.usage,
            "interface_number": 0,
            "bus_type": 1,
        }
        self.node = HidNode(self.bus, path, [entry], report_descriptor(p, full_scale))

    @property
    def device_spec(self) -> str:
        return f"spacemouse:{self.path.decode()}"

    @property
    def env(self) -> dict[str, str]:
        return {
            "SASPROBE_HID_API": HID_API_FACTORY,
            BUS_ENV: str(self.bus.directory),
            "PYTHONPATH": str(REPO_ROOT),
        }

    def raw_axes(self, translation, rotation) -> list[int]:
        """The HID axes (x, y, z, rx, ry, rz) of a deflection, in counts."""

        def layout(v):
            right, up, toward = v
            return (right, toward, -up) if self.product.y_toward_user else (right, up, -toward)

        fractions = (*layout(translation), *layout(rotation))
        return [max(-32768, min(32767, round(f * self.full_scale))) for f in fractions]

    def set_cap(self, translation, rotation) -> None:
        axes = self.raw_axes(translation, rotation)
        if axes == self._axes:
            return  # on change only
        changed_t, changed_r = axes[:3] != self._axes[:3], axes[3:] != self._axes[3:]
        self._axes = axes
        if self.product.combined_report:
            self.node.send(bytes([1]) + struct.pack("<6h", *axes))
            return
        if changed_t:
            self.node.send(bytes([1]) + struct.pack("<3h", *axes[:3]))
        if changed_r:
            self.node.send(bytes([2]) + struct.pack("<3h", *axes[3:]))

    def set_keys(self, keys) -> None:
        """Hold exactly these keys (labels, or raw report bits as ints) down."""
        bits = 0
        for key in keys:
            bits |= 1 << (key if isinstance(key, int) else self.product.keys[key] - 0x100)
        self._bits = bits
        self.node.send(bytes([3]) + bits.to_bytes(-(-self.product.button_count // 8), "little"))

    def send(self, report: bytes) -> None:
        """A raw report (junk, battery, ...)."""
        self.node.send(report)

    def unplug(self) -> None:
        self.node.unplug()

    def replug(self) -> None:
        self._axes, self._bits = [0] * 6, 0  # a cap plugged back in starts at rest
        self.node.plug()

    def close(self) -> None:
        self.node.unplug()
        if self._own_bus:
            self.bus.close()


def launch(**options) -> EmulatedSpaceMouse:
    """One emulated device plugged in. Options: product (name), path, bus, full_scale, serial."""
    return EmulatedSpaceMouse(options.pop("product", "SpaceMouse Compact"), **options)
