"""3Dconnexion SpaceMouse family over HID (hidapi): an input-only 6-DOF device.

Reports (public descriptions: the 3Dconnexion developer forum's HID descriptor thread,
and the Wireshark/WebHID write-ups of the SpaceNavigator and SpaceMouse Wireless):
report 1 carries translation x, y, z as signed 16-bit little-endian values (newer models
append rotation rx, ry, rz in the same 12-byte report), report 2 carries rotation on
older models, report 3 the button bitmask; values span about ±350. Other report IDs
(LEDs, battery) are ignored.

How the daemon sees it: a device with `has_force_output=False` whose position is a
cursor moved by **rate control**. Deflecting the cap moves the cursor at a speed
proportional to the deflection (full deflection = `speed_mm_s`), twisting it turns the
cursor's orientation likewise; the cursor stays inside the workspace box, so pushing
against a face of the box is how a user drives the navigation cube along. Velocity is
the commanded rate. A deflection with no new report for `stale_s` is treated as
released (the cap sends reports continuously while deflected). Axes: the cap's +x is
the device's +X (right), pulling the cap up is +Y, pulling it toward you is +Z.
"""

from __future__ import annotations

import struct
import time

import numpy as np

from sasprobe.devices.base import (PHANTOM_OMNI_LIMITS, DeviceFault, DeviceInfo, DeviceLimits, DeviceOpenError,
                                   DeviceState)
from sasprobe.devices.support import HardwareDevice, factory_from_environment, quaternion_about, quaternion_multiply
from sasprobe.devices.transports import HidTransport, load_hidapi

VENDOR_3DCONNEXION = 0x256F
VENDOR_LOGITECH = 0x046D
# (vendor, product) → name; every product of vendor 0x256f counts as a 3Dconnexion device.
KNOWN_PRODUCTS = {
    (0x046D, 0xC603): "SpaceMouse Plus XT",
    (0x046D, 0xC605): "CADman",
    (0x046D, 0xC606): "SpaceMouse Classic",
    (0x046D, 0xC621): "SpaceBall 5000",
    (0x046D, 0xC623): "SpaceTraveler",
    (0x046D, 0xC625): "SpacePilot",
    (0x046D, 0xC626): "SpaceNavigator",
    (0x046D, 0xC627): "SpaceExplorer",
    (0x046D, 0xC628): "SpaceNavigator for Notebooks",
    (0x046D, 0xC629): "SpacePilot Pro",
    (0x046D, 0xC62B): "SpaceMouse Pro",
    (0x256F, 0xC62E): "SpaceMouse Wireless (cable)",
    (0x256F, 0xC62F): "SpaceMouse Wireless (receiver)",
    (0x256F, 0xC631): "SpaceMouse Pro Wireless (cable)",
    (0x256F, 0xC632): "SpaceMouse Pro Wireless (receiver)",
    (0x256F, 0xC633): "SpaceMouse Enterprise",
    (0x256F, 0xC635): "SpaceMouse Compact",
    (0x256F, 0xC652): "3Dconnexion Universal Receiver",
}

REPORT_TRANSLATION, REPORT_ROTATION, REPORT_BUTTONS = 1, 2, 3
FULL_SCALE = 350.0
DEADBAND = 8.0  # counts; a cap at rest drifts by a few

# No force reaches the device (max force 0, has_force_output False). The daemon's engine
# still computes the contact so the proxy stays on the surface in the picture; its spring
# and damping are bounded like an Omni-class arm's, since nothing is rendered by hand.
SPACEMOUSE_LIMITS = DeviceLimits(
    max_force_n=0.0, continuous_force_n=0.0,
    max_stiffness_n_per_mm=PHANTOM_OMNI_LIMITS.max_stiffness_n_per_mm,
    max_damping_n_s_per_m=PHANTOM_OMNI_LIMITS.max_damping_n_s_per_m,
    workspace_min_mm=(-100.0, -100.0, -100.0), workspace_max_mm=(100.0, 100.0, 100.0),
    nominal_rate_hz=1000.0,  # reports come at ~60 Hz; the cursor integrates at any polling rate
    has_force_output=False,
)


def is_spacemouse(vendor_id: int, product_id: int) -> bool:
    return vendor_id == VENDOR_3DCONNEXION or (vendor_id, product_id) in KNOWN_PRODUCTS


def product_name(vendor_id: int, product_id: int) -> str:
    return KNOWN_PRODUCTS.get((vendor_id, product_id), "3Dconnexion device")


def parse_report(report: bytes) -> dict | None:
    """{'translation': (3,), 'rotation': (3,), 'buttons': int} (any subset), or None if malformed."""
    if not report:
        return None
    rid, body = report[0], report[1:]
    if rid == REPORT_TRANSLATION:
        if len(body) >= 12:
            values = struct.unpack_from("<6h", body)
            return {"translation": np.array(values[:3], float), "rotation": np.array(values[3:], float)}
        if len(body) >= 6:
            return {"translation": np.array(struct.unpack_from("<3h", body), float)}
        return None
    if rid == REPORT_ROTATION:
        return {"rotation": np.array(struct.unpack_from("<3h", body), float)} if len(body) >= 6 else None
    if rid == REPORT_BUTTONS:
        return {"buttons": int.from_bytes(body, "little")} if body else None
    return {}  # LEDs, battery, vendor reports: not ours to interpret


def _rate(raw: np.ndarray) -> np.ndarray:
    """HID axes → device-frame rate in [-1, 1] (X right, Y up, Z toward the user)."""
    x, y, z = (np.where(np.abs(raw) > DEADBAND, raw, 0.0) / FULL_SCALE).clip(-1.0, 1.0)
    return np.array([x, -z, y])


class SpaceMouseDevice(HardwareDevice):
    def __init__(self, path: bytes | str | None = None, *, hid_api=None, speed_mm_s: float = 100.0,
                 turn_rad_s: float = 1.5, stale_s: float = 0.25):
        self.path = path.encode() if isinstance(path, str) else path
        self.speed_mm_s, self.turn_rad_s, self.stale_s = speed_mm_s, turn_rad_s, stale_s
        self._api = hid_api
        self._transport: HidTransport | None = None
        self.model = "SpaceMouse"
        self.rejected_frames = 0
        self._translation = np.zeros(3)
        self._rotation = np.zeros(3)
        self._buttons = 0
        self._last_report = 0.0
        self._last_t_ns: int | None = None
        self.position = np.zeros(3)
        self.orientation = np.array([1.0, 0.0, 0.0, 0.0])

    @property
    def info(self) -> DeviceInfo:
        return DeviceInfo(kind="spacemouse", model=self.model, limits=SPACEMOUSE_LIMITS,
                          serial=self.path.decode(errors="replace") if self.path else "",
                          details={"rate_control": True, "speed_mm_s": self.speed_mm_s,
                                   "rejected_frames": self.rejected_frames})

    def _hid(self):
        if self._api is None:
            self._api = load_hidapi()
        return self._api

    def _find(self) -> tuple[bytes, str]:
        candidates = [d for d in self._hid().enumerate() if is_spacemouse(d["vendor_id"], d["product_id"])]
        if self.path is not None:
            for d in candidates:
                if d["path"] == self.path:
                    return d["path"], product_name(d["vendor_id"], d["product_id"])
            return self.path, "SpaceMouse"  # open it anyway; the error names the path
        if not candidates:
            raise DeviceOpenError("no 3Dconnexion SpaceMouse found (is it plugged in? `sasprobe devices` lists "
                                  "HID devices; without permission on /dev/hidraw* it is invisible: see the README)")
        # the multi-axis controller interface (usage page 1, usage 8) when one is listed
        candidates.sort(key=lambda d: (d.get("usage_page"), d.get("usage")) != (1, 8))
        d = candidates[0]
        return d["path"], product_name(d["vendor_id"], d["product_id"])

    def open(self) -> None:
        path, self.model = self._find()
        self._transport = HidTransport(path, hid_api=self._hid(), label=self.model)
        self._transport.open()
        self.path = path
        self._translation[:] = 0.0
        self._rotation[:] = 0.0
        self._last_t_ns = None

    def close(self) -> None:
        if self._transport is not None:
            self._transport.close()
            self._transport = None

    def _drain(self) -> None:
        if self._transport is None:
            raise DeviceFault("SpaceMouse is not open")
        for _ in range(64):  # bounded: a flood of reports cannot stall the loop
            report = self._transport.read(64, 0.0)
            if not report:
                return
            parsed = parse_report(report)
            if parsed is None:
                self.rejected_frames += 1
                continue
            if "translation" in parsed:
                self._translation = parsed["translation"]
            if "rotation" in parsed:
                self._rotation = parsed["rotation"]
            if "buttons" in parsed:
                self._buttons = parsed["buttons"]
            if parsed:
                self._last_report = time.monotonic()

    def read(self) -> DeviceState:
        self._drain()
        now = time.monotonic_ns()
        if time.monotonic() - self._last_report > self.stale_s:
            self._translation = np.zeros(3)
            self._rotation = np.zeros(3)
        velocity = _rate(self._translation) * self.speed_mm_s
        omega = _rate(self._rotation) * self.turn_rad_s
        if self._last_t_ns is not None:
            dt = (now - self._last_t_ns) * 1e-9
            lo, hi = np.asarray(SPACEMOUSE_LIMITS.workspace_min_mm), np.asarray(SPACEMOUSE_LIMITS.workspace_max_mm)
            self.position = np.clip(self.position + velocity * dt, lo, hi)
            angle = float(np.linalg.norm(omega)) * dt
            if angle > 0.0:
                self.orientation = quaternion_multiply(quaternion_about(omega, angle), self.orientation)
                self.orientation /= np.linalg.norm(self.orientation)
        self._last_t_ns = now
        return DeviceState(t_ns=now, position_mm=self.position.copy(), orientation=self.orientation.copy(),
                           velocity_mm_s=velocity, buttons=self._buttons, calibrated=True)

    def write_force(self, force_n) -> None:
        """No force output: ignored."""


def create(argument: str | None = None, **options) -> SpaceMouseDevice:
    """`spacemouse[:PATH]` (PATH as `sasprobe devices` prints it). Options: hid_api, speed_mm_s.

    Without `hid_api`, SASPROBE_HID_API=module:function names a factory of a stand-in for
    the hidapi module (how the test suite points a daemon subprocess at an emulated puck).
    """
    hid_api = options.get("hid_api") or factory_from_environment("SASPROBE_HID_API")
    return SpaceMouseDevice(argument or None, hid_api=hid_api, speed_mm_s=float(options.get("speed_mm_s", 100.0)))
