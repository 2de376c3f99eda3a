"""The SpaceMouse as a HapticDevice: an input-only 6-DoF cap driving a cursor by rate control.

How the daemon sees it: a device with `has_force_output=False` whose position is a
cursor. Deflecting the cap moves the cursor at a speed proportional to the deflection
(full deflection = `speed_mm_s`), twisting it turns the cursor's orientation likewise
(full twist = `turn_rad_s`); the cursor stays inside a ±100 mm box, so pushing against
a face of the box is how a user drives the navigation cube along. Velocity is the
commanded rate.

A SpaceMouse reports on change only: a cap held still off-centre sends nothing more, and
keeps moving the cursor until a report says otherwise (spacenavd's example spnavrc,
`repeat-interval`, describes applications whose motion then stops). A vanished
device is a read error, never a silence.

Reads never wait: the hidapi handle is set non-blocking when opened, and each `read()`
drains at most 64 waiting reports (hidapi linux/hid.c: `hid_read` on a blocking handle
would wait for the next report, which a cap at rest never sends).
"""

from __future__ import annotations

import dataclasses
import time

import numpy as np
from sasprobe.devices.base import (
    PHANTOM_OMNI_LIMITS,
    DeviceFault,
    DeviceInfo,
    DeviceOpenError,
    DeviceState,
)
from sasprobe.devices.hardware import HardwareDriver, factory_from_environment
from sasprobe.devices.kinematics import quaternion_about, quaternion_multiply
from sasprobe.devices.spacemouse import models, protocol
from sasprobe.devices.transports import HidTransport, load_hidapi

# No force reaches the device. The daemon's engine still computes the contact so the
# proxy stays on the surface in the picture; its spring and damping are bounded like an
# Omni-class arm's, since nothing is rendered to a hand.
SPACEMOUSE_LIMITS = dataclasses.replace(
    PHANTOM_OMNI_LIMITS,
    max_force_n=0.0,
    continuous_force_n=0.0,
    workspace_min_mm=(-100.0, -100.0, -100.0),
    workspace_max_mm=(100.0, 100.0, 100.0),
    nominal_rate_hz=1000.0,  # the cursor integrates at any polling rate
    has_force_output=False,
)
MAX_REPORTS_PER_READ = 64  # bounded: a flood of reports cannot stall the loop


class SpaceMouseDevice(HardwareDriver):
    def __init__(
        self,
        path: bytes | str | None = None,
        *,
        hid_api=None,
        speed_mm_s: float = 100.0,
        turn_rad_s: float = 1.5,
    ):
        self.path = path.encode() if isinstance(path, str) else path
        self.speed_mm_s, self.turn_rad_s = speed_mm_s, turn_rad_s
        self._api = hid_api
        self._transport: HidTransport | None = None
        self.ids = (0, 0)
        self.model = models.Model("SpaceMouse", newer_axes=True)
        self.full_scale = float(protocol.ASSUMED_FULL_SCALE)
        self.rejected_frames = 0
        self._raw = np.zeros(6)  # the last reported axes, as the device numbers them
        self._bits = 0
        self._last_t_ns: int | None = None
        self.position = np.zeros(3)
        self.orientation = np.array([1.0, 0.0, 0.0, 0.0])

    @property
    def info(self) -> DeviceInfo:
        return DeviceInfo(
            kind="spacemouse",
            model=self.model.name,
            limits=SPACEMOUSE_LIMITS,
            serial=self.path.decode(errors="replace") if self.path else "",
            details={
                "usb_id": f"{self.ids[0]:04x}:{self.ids[1]:04x}",
                "rate_control": True,
                "speed_mm_s": self.speed_mm_s,
                "full_scale_counts": self.full_scale,
                "newer_axes": self.model.newer_axes,
                "rejected_frames": self.rejected_frames,
            },
        )

    def _hid(self):
        if self._api is None:
            self._api = load_hidapi()
        return self._api

    def _find(self) -> dict:
        """The hidapi entry to open: the named path, or the first 6-DoF device listed."""
        listed = self._hid().enumerate()
        if self.path is not None:
            entries = [d for d in listed if d["path"] == self.path]
            if not entries:
                raise DeviceOpenError(
                    f"no HID device at {self.path.decode(errors='replace')} (unplugged? "
                    "`sasprobe devices` lists the SpaceMice it sees)"
                )
        else:
            entries = listed
        usable = [
            d
            for d in entries
            if models.is_six_dof(d["vendor_id"], d["product_id"], models.interface_usage(d))
        ]
        if not usable:
            if self.path is not None:
                raise DeviceOpenError(
                    f"{self.path.decode(errors='replace')}: "
                    f"{models.refusal(entries[0]['vendor_id'], entries[0]['product_id'])}"
                )
            raise DeviceOpenError(
                "no 3Dconnexion SpaceMouse found (is it plugged in? `sasprobe devices` lists HID "
                "devices; without permission on /dev/hidraw* it is invisible: see "
                "docs/connect-your-arm.md)"
            )
        # a device's multi-axis controller interface when hidapi lists one
        usable.sort(key=lambda d: models.interface_usage(d) != models.MULTI_AXIS_CONTROLLER)
        return usable[0]

    def open(self) -> None:
        entry = self._find()
        self.path = entry["path"]
        self.ids = (entry["vendor_id"], entry["product_id"])
        transport = HidTransport(
            self.path, hid_api=self._hid(), label=models.product_name(*self.ids)
        )
        transport.open()
        self._transport = transport
        summary = None
        descriptor = transport.report_descriptor()
        if descriptor:
            summary = protocol.scan_descriptor(descriptor)
        if self.ids == models.UNIVERSAL_RECEIVER:
            self.model = models.receiver_model(summary.buttons if summary else None)
        else:
            self.model = models.MODELS[self.ids]
        self.full_scale = (
            float(summary.axis_maximum)
            if summary and summary.axis_maximum
            else float(protocol.ASSUMED_FULL_SCALE)
        )
        self._raw = np.zeros(6)  # at rest until the first report says otherwise
        self._bits = 0
        self._last_t_ns = None

    def close(self) -> None:
        if self._transport is not None:
            self._transport.close()
            self._transport = None

    def _drain(self) -> None:
        if self._transport is None:
            raise DeviceFault("SpaceMouse is not open")
        for _ in range(MAX_REPORTS_PER_READ):
            report = self._transport.read(64, 0.0)
            if not report:
                return
            parsed = protocol.parse_report(report)
            if parsed is None:
                self.rejected_frames += 1
                continue
            if "translation" in parsed:
                self._raw[:3] = parsed["translation"]
            if "rotation" in parsed:
                self._raw[3:] = parsed["rotation"]
            if "buttons" in parsed:
                self._bits = parsed["buttons"]

    def _rates(self) -> tuple[np.ndarray, np.ndarray]:
        """(translation, rotation) rates in [-1, 1], device frame, dead zone applied."""
        raw = np.where(np.abs(self._raw) >= protocol.DEAD_THRESHOLD, self._raw, 0.0)
        rates = (protocol.device_frame(raw, self.model.newer_axes) / self.full_scale).clip(
            -1.0, 1.0
        )
        return rates[:3], rates[3:]

    def read(self) -> DeviceState:
        self._drain()
        now = time.monotonic_ns()
        translation, rotation = self._rates()
        velocity = translation * self.speed_mm_s
        omega = rotation * self.turn_rad_s
        if self._last_t_ns is not None:
            dt = (now - self._last_t_ns) * 1e-9
            lo, hi = (
                np.asarray(SPACEMOUSE_LIMITS.workspace_min_mm),
                np.asarray(SPACEMOUSE_LIMITS.workspace_max_mm),
            )
            self.position = np.clip(self.position + velocity * dt, lo, hi)
            angle = float(np.linalg.norm(omega)) * dt
            if angle > 0.0:
                self.orientation = quaternion_multiply(
                    quaternion_about(omega, angle), self.orientation
                )
                self.orientation /= np.linalg.norm(self.orientation)
        self._last_t_ns = now
        return DeviceState(
            t_ns=now,
            position_mm=self.position.copy(),
            orientation=self.orientation.copy(),
            velocity_mm_s=velocity,
            buttons=protocol.button_mask(self._bits, self.model.buttons),
            calibrated=True,
        )

    def write_force(self, force_n) -> None:
        """No force output: ignored."""


def create(argument: str | None = None, **options) -> SpaceMouseDevice:
    """`spacemouse[:PATH]` (PATH as `sasprobe devices` prints it). Options: hid_api, speed_mm_s.

    Without `hid_api`, SASPROBE_HID_API=module:function names a factory of a stand-in for
    the hidapi module (how the test suite points a daemon subprocess at an emulated cap).
    """
    hid_api = options.get("hid_api") or factory_from_environment("SASPROBE_HID_API")
    return SpaceMouseDevice(
        argument or None, hid_api=hid_api, speed_mm_s=float(options.get("speed_mm_s", 100.0))
    )
