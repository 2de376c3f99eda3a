"""A SpaceMouse behind a fake at the hidapi boundary.

`FakeHidApi` has the surface of the `hid` module the driver uses (`enumerate()`,
`device()`); its handles have hidapi's `open_path`, `read(max_length, timeout_ms)`,
`write`, `close`. `EmulatedSpaceMouse` produces the public report layout: report 1 with
translation (and, on newer models, rotation: 12 bytes), report 2 with rotation,
report 3 with buttons. Unplugging makes reads raise OSError, as hidapi does.
"""

from __future__ import annotations

import collections
import struct
import threading
import time


class EmulatedSpaceMouse:
    def __init__(self, path: bytes = b"/dev/hidraw-emu0", vendor_id: int = 0x256F, product_id: int = 0xC635,
                 combined_reports: bool = True):
        self.path = path
        self.vendor_id, self.product_id = vendor_id, product_id
        self.combined_reports = combined_reports  # 12-byte report 1 (newer) or reports 1 + 2 (older)
        self.reports: collections.deque[bytes] = collections.deque()
        self.plugged = True
        self.lock = threading.Lock()

    def push(self, report: bytes) -> None:
        with self.lock:
            self.reports.append(bytes(report))

    def move(self, translation, rotation) -> None:
        t = [int(v) for v in translation]
        r = [int(v) for v in rotation]
        if self.combined_reports:
            self.push(bytes([1]) + struct.pack("<6h", *t, *r))
        else:
            self.push(bytes([1]) + struct.pack("<3h", *t))
            self.push(bytes([2]) + struct.pack("<3h", *r))

    def press(self, buttons: int) -> None:
        self.push(bytes([3]) + buttons.to_bytes(2, "little"))

    def unplug(self) -> None:
        self.plugged = False

    def replug(self) -> None:
        with self.lock:
            self.reports.clear()
        self.plugged = True

    def descriptor(self) -> dict:
        return {"path": self.path, "vendor_id": self.vendor_id, "product_id": self.product_id,
                "serial_number": "", "release_number": 0x0100, "manufacturer_string": "3Dconnexion",
                "product_string": "SpaceMouse Compact", "usage_page": 1, "usage": 8, "interface_number": 0}


class _FakeHandle:
    def __init__(self, api: FakeHidApi):
        self.api = api
        self.dev: EmulatedSpaceMouse | None = None

    def open_path(self, path: bytes) -> None:
        dev = self.api.devices.get(path)
        if dev is None or not dev.plugged:
            raise OSError("open failed")
        self.dev = dev

    def read(self, max_length: int, timeout_ms: int = 0) -> list[int]:
        dev = self.dev
        if dev is None:
            raise ValueError("not open")
        deadline = time.monotonic() + timeout_ms / 1000.0
        while True:
            if not dev.plugged:
                raise OSError("read error")
            with dev.lock:
                if dev.reports:
                    return list(dev.reports.popleft()[:max_length])
            if time.monotonic() >= deadline:
                return []
            time.sleep(0.001)

    def write(self, data) -> int:
        if self.dev is None or not self.dev.plugged:
            raise OSError("write error")
        return len(data)

    def close(self) -> None:
        self.dev = None


class FakeHidApi:
    def __init__(self, *devices: EmulatedSpaceMouse):
        self.devices = {d.path: d for d in devices}

    def enumerate(self, vendor_id: int = 0, product_id: int = 0) -> list[dict]:
        return [d.descriptor() for d in self.devices.values() if d.plugged
                and vendor_id in (0, d.vendor_id) and product_id in (0, d.product_id)]

    def device(self) -> _FakeHandle:
        return _FakeHandle(self)


def api_from_environment() -> FakeHidApi:
    """Factory for SASPROBE_HID_API in subprocess tests: a puck whose user deflects the cap
    right (half way) for a second, then left for a second, and so on, reporting at 60 Hz."""
    puck = EmulatedSpaceMouse()

    def user() -> None:
        start = time.monotonic()
        while True:
            phase = int(time.monotonic() - start) % 2
            puck.move([175 if phase == 0 else -175, 0, 0], [0, 0, 0])
            time.sleep(1 / 60)

    threading.Thread(target=user, name="spacemouse-user", daemon=True).start()
    return FakeHidApi(puck)
