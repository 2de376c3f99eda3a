"""SpaceMouse HID input reports, the report descriptor, and the axes in the device frame.

Reports (spacenavd's raw-HID reader, src/dev_usb_freebsd.c `read_hid`, commit bac572a):
report 1 carries signed 16-bit little-endian axes, three (x, y, z) or, in a 12-byte
report, all six (x, y, z, rx, ry, rz); report 2 the rotations rx, ry, rz; report 3 the
button bitmask; other ids (23 is the battery level) carry no motion.

Axes: spacenavd first brings every model to one axis order (src/dev.c `read_device`:
with DF_SWAPYZ axis indices 1<->2 and 4<->5 swap, with DF_INVYZ every axis but 0 and 3
changes sign). Those normalised axes are left-handed with z away from the user: libspnav
moves an object by (x, y, -z) and turns it about (rx, ry, -rz) in OpenGL's frame
(FreeSpacenav/libspnav bcc2e295, src/util.c `spnav_posrot_moveobj`). So the device
frame (x right, y up, z toward the user) is the normalised axes with z negated.

Scale: each axis's range is the Logical Minimum/Maximum its report descriptor declares
(USB HID 1.11 §6.2.2.7); spacenavd maps that range onto ±500 (src/dev_usb_linux.c
`map_range`), we onto ±1. Without a readable descriptor we assume ±350, the range the
SpaceNavigator class declares (not stated by spacenavd).
"""

from __future__ import annotations

import struct
from dataclasses import dataclass

import numpy as np

REPORT_TRANSLATION, REPORT_ROTATION, REPORT_BUTTONS = 1, 2, 3
ASSUMED_FULL_SCALE = 350
DEAD_THRESHOLD = 2  # counts: spacenavd's default per-axis dead zone (src/cfgfile.c `default_cfg`)

_SWAP_YZ = (0, 2, 1, 3, 5, 4)  # spacenavd's DF_SWAPYZ index table
_INVERT_YZ = np.array([1, -1, -1, 1, -1, -1])  # DF_INVYZ: every axis but 0 and 3
_LEFT_TO_RIGHT_HANDED = np.array([1, 1, -1, 1, 1, -1])  # libspnav: z and rz toward the user


def parse_report(report: bytes) -> dict | None:
    """{'translation': (3,), 'rotation': (3,), 'buttons': int} (any subset), or None if
    malformed."""
    if not report:
        return None
    rid, body = report[0], report[1:]
    if rid == REPORT_TRANSLATION:
        if len(body) >= 12:
            values = struct.unpack_from("<6h", body)
            return {
                "translation": np.array(values[:3], float),
                "rotation": np.array(values[3:], float),
            }
        if len(body) >= 6:
            return {"translation": np.array(struct.unpack_from("<3h", body), float)}
        return None
    if rid == REPORT_ROTATION:
        return (
            {"rotation": np.array(struct.unpack_from("<3h", body), float)}
            if len(body) >= 6
            else None
        )
    if rid == REPORT_BUTTONS:
        return {"buttons": int.from_bytes(body, "little")} if body else None
    return {}  # battery, LEDs, vendor reports: no motion


def device_frame(raw: np.ndarray, newer_axes: bool) -> np.ndarray:
    """Six HID axes (x, y, z, rx, ry, rz as reported) → (translation, rotation) in the device
    frame."""
    raw = np.asarray(raw, dtype=float)
    normalised = raw.copy()
    if newer_axes:
        normalised[list(_SWAP_YZ)] = raw  # spacenavd: value of axis i goes to axis swap[i]
        normalised = normalised * _INVERT_YZ
    return normalised * _LEFT_TO_RIGHT_HANDED


def button_mask(bits: int, remap: dict[int, int] | None) -> int:
    """Report-3 bits → the model's button numbers as a bitmask (bit b = button b pressed)."""
    if remap is None:
        return bits
    mask = 0
    for bit, button in remap.items():
        if bits >> bit & 1:
            mask |= 1 << button
    return mask


@dataclass(frozen=True)
class DescriptorSummary:
    buttons: int  # button usages in input reports
    # the largest Logical Maximum of the X..Rz axes, None when none is declared
    axis_maximum: int | None


_USAGE_PAGE_DESKTOP, _USAGE_PAGE_BUTTON = 0x01, 0x09
_AXES = range(0x30, 0x36)  # X, Y, Z, Rx, Ry, Rz


def scan_descriptor(descriptor: bytes) -> DescriptorSummary:
    """The button count and axis range of a HID report descriptor (HID 1.11 §6.2.2 items)."""
    usage_page = logical_maximum = report_count = 0
    usages: list[int] = []
    buttons, axis_maximum = 0, None
    i = 0
    while i < len(descriptor):
        prefix = descriptor[i]
        if prefix == 0xFE:  # long item: size byte, tag byte, data
            i += 3 + (descriptor[i + 1] if i + 1 < len(descriptor) else 0)
            continue
        size = (0, 1, 2, 4)[prefix & 0x03]
        data = descriptor[i + 1 : i + 1 + size]
        value = int.from_bytes(data, "little") if data else 0
        kind, tag = (prefix >> 2) & 0x03, prefix >> 4
        i += 1 + size
        if kind == 1:  # global
            if tag == 0x0:
                usage_page = value
            elif tag == 0x2:
                logical_maximum = int.from_bytes(data, "little", signed=True) if data else 0
            elif tag == 0x9:
                report_count = value
        elif kind == 2:  # local
            if tag == 0x0:
                usages.append(value)
            elif tag == 0x2 and usages:  # usage maximum after a usage minimum: the range
                usages.extend(range(usages.pop(), value + 1))
            elif tag == 0x1:
                usages.append(value)
        elif kind == 0:  # main
            if tag == 0x8 and not value & 0x01:  # a data (not constant) input item
                if usage_page == _USAGE_PAGE_BUTTON:
                    buttons += report_count
                elif usage_page == _USAGE_PAGE_DESKTOP and any(u in _AXES for u in usages):
                    axis_maximum = max(axis_maximum or 0, logical_maximum)
            usages = []  # local items end with each main item
    return DescriptorSummary(buttons, axis_maximum)
