"""What is plugged in: serial ports, SpaceMouse HID devices, USB arms with known ids, Force
Dimension arms the DHD library counts, Inverse3 arms an Inverse Service lists.

Each finding carries the `--device` string that selects it. The sources (pyserial's
port list, the hidapi module, a pyusb backend, the DHD library, the service's address)
can be passed in; without them the SASPROBE_HID_API, SASPROBE_USB_BACKEND,
SASPROBE_DHD_LIBRARY and SASPROBE_INVERSE_SERVICE hooks apply too, which is how tests
point `sasprobe devices` in a subprocess at their emulators.
"""

from __future__ import annotations

import ctypes.util
import os
from dataclasses import asdict, dataclass
from pathlib import Path

from sasprobe.devices.base import DeviceOpenError
from sasprobe.devices.falcon.models import PRODUCT_ID as FALCON_PRODUCT_ID
from sasprobe.devices.falcon.models import VENDOR_ID as FALCON_VENDOR_ID
from sasprobe.devices.forcedimension.driver import list_arms as list_dhd_arms
from sasprobe.devices.hardware import factory_from_environment
from sasprobe.devices.inverse3.driver import list_arms as list_inverse3_arms
from sasprobe.devices.inverse3.protocol import DEFAULT_URL as INVERSE_SERVICE_URL
from sasprobe.devices.spacemouse import models as spacemouse_models
from sasprobe.devices.transports import load_hidapi


@dataclass(frozen=True)
class Found:
    transport: str  # "serial", "hid", "usb"
    path: str
    vendor_id: int | None
    product_id: int | None
    description: str
    device: str | None  # the --device string, None when sasprobe cannot drive it directly
    note: str = ""

    def as_dict(self) -> dict:
        d = asdict(self)
        for key in ("vendor_id", "product_id"):
            d[key] = None if d[key] is None else f"{d[key]:04x}"
        return d


# Serial (CDC-ACM) devices recognised by USB id:
# (vid, pid) → (description, --device template, note).
KNOWN_SERIAL = {
    (0x16C0, 0x0483): (
        "Teensy USB serial (WoodenHaptics / Polhem firmware)",
        "woodenhaptics:{port}",
        "",
    ),
    (0x0301, 0x2988): (
        "3D Systems Touch",
        "openhaptics",
        "its serial protocol is not public: sasprobe drives it through OpenHaptics",
    ),
    (0x2988, 0x0302): (
        "3D Systems Touch",
        "openhaptics",
        "its serial protocol is not public: sasprobe drives it through OpenHaptics",
    ),
}
KNOWN_USB = {(FALCON_VENDOR_ID, FALCON_PRODUCT_ID): ("Novint Falcon", "falcon")}


def serial_ports(comports=None) -> tuple[list[Found], list[str]]:
    """USB serial ports (every arm sasprobe drives over serial is a USB device); others in a
    note."""
    if comports is None:
        from serial.tools.list_ports import comports
    found, other = [], []
    for port in sorted(comports(), key=lambda p: p.device):
        if port.vid is None:
            other.append(port.device)
            continue
        known = KNOWN_SERIAL.get((port.vid, port.pid))
        if known:
            description, template, note = known
            device = template.format(port=port.device)
        else:
            description = (
                port.description
                if port.description and port.description != "n/a"
                else "serial port"
            )
            device = f"woodenhaptics:{port.device}"
            note = f"or haply:{port.device} for a Haply 2DIY"
        found.append(Found("serial", port.device, port.vid, port.pid, description, device, note))
    notes = (
        [
            f"{len(other)} serial port(s) without a USB id not listed ({', '.join(other[:3])}"
            f"{', ...' if len(other) > 3 else ''}): no supported arm uses one"
        ]
        if other
        else []
    )
    return found, notes


def hid_devices(hid_api=None) -> list[Found]:
    """The 6-DoF 3Dconnexion devices (spacenavd's list; CadMice, keyboards and numpads left out)."""
    if hid_api is None:
        hid_api = factory_from_environment("SASPROBE_HID_API") or load_hidapi()
    by_device: dict[tuple, dict] = {}  # one entry per device: its multi-axis controller interface
    for d in hid_api.enumerate():
        usage = spacemouse_models.interface_usage(d)
        if not spacemouse_models.is_six_dof(d["vendor_id"], d["product_id"], usage):
            continue
        key = (d["vendor_id"], d["product_id"], d.get("serial_number") or "", d["path"])
        if key not in by_device or usage == spacemouse_models.MULTI_AXIS_CONTROLLER:
            by_device[key] = d
    found = []
    for d in by_device.values():
        path = (
            d["path"].decode(errors="replace") if isinstance(d["path"], bytes) else str(d["path"])
        )
        found.append(
            Found(
                "hid",
                path,
                d["vendor_id"],
                d["product_id"],
                spacemouse_models.product_name(d["vendor_id"], d["product_id"]),
                f"spacemouse:{path}",
                "input only: moves the cursor and navigation cube, no force",
            )
        )
    return sorted(found, key=lambda f: f.path)


def usb_devices(backend=None) -> tuple[list[Found], list[str]]:
    """Known USB arms, through pyusb (or sysfs when libusb is missing)."""
    import usb.core

    if backend is None:
        backend = factory_from_environment("SASPROBE_USB_BACKEND")
    try:
        devices = [
            (d.idVendor, d.idProduct, f"usb bus {d.bus} address {d.address}")
            for d in usb.core.find(find_all=True, backend=backend)
        ]
        notes = []
    except usb.core.NoBackendError:
        devices = _sysfs_usb()
        notes = [
            "libusb-1.0 is not installed: USB ids read from sysfs, but drivers that use pyusb "
            "(falcon) need it (Debian/Ubuntu: sudo apt install libusb-1.0-0)"
        ]
    found = []
    for vid, pid, where in devices:
        known = KNOWN_USB.get((vid, pid))
        if known:
            found.append(
                Found(
                    "usb",
                    where,
                    vid,
                    pid,
                    known[0],
                    known[1],
                    "the firmware file is needed once per power-up: --device falcon:FIRMWARE",
                )
            )
    return found, notes


def _sysfs_usb(root: Path = Path("/sys/bus/usb/devices")) -> list[tuple[int, int, str]]:
    out = []
    if not root.is_dir():
        return out
    for dev in sorted(root.iterdir()):
        try:
            vid = int((dev / "idVendor").read_text().strip(), 16)
            pid = int((dev / "idProduct").read_text().strip(), 16)
        except (OSError, ValueError):
            continue
        out.append((vid, pid, f"usb {dev.name}"))
    return out


def openhaptics_note() -> str:
    path = os.environ.get("SASPROBE_HD_LIBRARY") or ctypes.util.find_library("HD")
    if path:
        return (
            f"OpenHaptics HD library found ({path}): PHANTOM Omni/Touch arms open with "
            "--device openhaptics"
        )
    return "OpenHaptics is not installed: PHANTOM Omni/Touch arms need it (--device openhaptics)"


def dhd_arms(library: str | None = None) -> tuple[list[Found], list[str]]:
    """Force Dimension arms, through the DHD library when it is there."""
    try:
        arms = list_dhd_arms(library)
    except DeviceOpenError as exc:
        return [], [f"Force Dimension arms not listed: {exc}"]
    found = []
    for arm in arms:
        device = "forcedimension" if arm["index"] == 0 else f"forcedimension:{arm['index']}"
        if "error" in arm:
            description = "Force Dimension arm"
            note = f"did not open now ({arm['error']}): in use by another program?"
        else:
            serial = f" serial {arm['serial']}" if arm["serial"] else ""
            description, note = f"Force Dimension {arm['model']}{serial}", ""
        found.append(Found("dhd", f"index {arm['index']}", None, None, description, device, note))
    return found, []


def inverse3_arms(url: str | None = None) -> tuple[list[Found], list[str]]:
    """Inverse3 arms an Inverse Service answering at `url` lists (default: its default port)."""
    url = url or os.environ.get("SASPROBE_INVERSE_SERVICE") or INVERSE_SERVICE_URL
    try:
        arms = list_inverse3_arms(url)
    except DeviceOpenError as exc:
        return [], [f"Haply Inverse3 arms not listed: {exc}"]
    device = "inverse3" if url == INVERSE_SERVICE_URL else f"inverse3:{url}"
    found = [
        Found(
            "websocket",
            url,
            None,
            None,
            f"{arm['model']} {arm['device_id']}",
            device,
            "" if arm["calibrated"] else "not calibrated yet: let it self-calibrate",
        )
        for arm in arms
    ]
    return found, []


def discover(
    *, comports=None, hid_api=None, usb_backend=None, dhd_library=None, inverse_url=None
) -> tuple[list[Found], list[str]]:
    """(everything found, notes about what could not be looked at)."""
    found, notes = serial_ports(comports)
    try:
        found += hid_devices(hid_api)
    except (ImportError, OSError, DeviceOpenError) as exc:
        notes.append(f"HID devices not listed: {exc}")
    usb_found, usb_notes = usb_devices(usb_backend)
    found += usb_found
    notes += usb_notes
    notes.append(openhaptics_note())
    for more_found, more_notes in (dhd_arms(dhd_library), inverse3_arms(inverse_url)):
        found += more_found
        notes += more_notes
    return found, notes
