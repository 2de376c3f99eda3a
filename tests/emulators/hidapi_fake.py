"""A stand-in for the `hid` module (hidapi) over emulated hidraw nodes, with hidapi's semantics.

Written from trezor/cython-hidapi hid.pyx (commit 2924f2c7) and libusb/hidapi
linux/hid.c (commit 49578246):
- `enumerate()` lists one dict per (path, usage page, usage) pair, the keys of hid.pyx;
- `device().read(n, timeout_ms=0)`: a timeout above 0 calls `hid_read_timeout` (poll for
  that long, then read); 0 calls `hid_read`, which is `hid_read_timeout(-1)` on a
  blocking handle (a plain blocking read: it waits for the next report, however long)
  and `hid_read_timeout(0)` once `set_nonblocking(1)` was called (poll without waiting);
  poll reporting POLLERR/POLLHUP/POLLNVAL, or a failed read, is -1, which hid.pyx raises
  as IOError('read error'); each read returns one report, cut to n bytes;
- a new handle blocks (hidapi sets `blocking = 1` when it opens a device).

The node: a `HidBus` folder holds `devices.json` (what enumeration lists) and one
SOCK_SEQPACKET Unix socket per node, so one packet is one report, as one read of a
hidraw node is, and a daemon in another process reaches the same devices
(SASPROBE_HID_BUS names the folder; `module_from_environment` is the factory for
SASPROBE_HID_API). A device side plugs in by listening on its socket, sends each input
report to every open handle, and unplugs by closing it all (the host sees POLLHUP).
"""

from __future__ import annotations

import json
import os
import select
import shutil
import socket
import tempfile
import threading
from pathlib import Path

BUS_ENV = "SASPROBE_HID_BUS"


class HidBus:
    """The folder of emulated hidraw nodes (one per device side plugged in)."""

    def __init__(self, directory: str | Path | None = None):
        # short: a Unix socket path is limited to ~100 bytes
        self.directory = Path(directory) if directory else Path(tempfile.mkdtemp(prefix="hid"))
        self._lock = threading.Lock()
        self._entries: dict[str, list[dict]] = {}
        self._publish()

    @property
    def listing(self) -> Path:
        return self.directory / "devices.json"

    def socket_path(self, hidraw_path: bytes) -> str:
        return str(self.directory / (hidraw_path.decode().strip("/").replace("/", "_") + ".sock"))

    def plug(self, hidraw_path: bytes, entries: list[dict]) -> None:
        with self._lock:
            self._entries[hidraw_path.decode()] = entries
            self._publish()

    def unplug(self, hidraw_path: bytes) -> None:
        with self._lock:
            self._entries.pop(hidraw_path.decode(), None)
            self._publish()

    def close(self) -> None:
        """Remove the folder (nodes still plugged in vanish with it)."""
        shutil.rmtree(self.directory, ignore_errors=True)

    def _publish(self) -> None:
        tmp = self.listing.with_suffix(".tmp")
        tmp.write_text(json.dumps([e for entries in self._entries.values() for e in entries]))
        os.replace(tmp, self.listing)  # a reader in another process never sees half a file


class HidNode:
    """The device side of one hidraw node: accepts handles, sends them input reports."""

    def __init__(
        self, bus: HidBus, hidraw_path: bytes, entries: list[dict], report_descriptor: bytes
    ):
        self.bus, self.path = bus, hidraw_path
        self.socket_path = bus.socket_path(hidraw_path)
        self.entries = [
            dict(
                e,
                path=hidraw_path.decode(),
                socket=self.socket_path,
                report_descriptor=report_descriptor.hex(),
            )
            for e in entries
        ]
        self._listener: socket.socket | None = None
        self._handles: list[socket.socket] = []
        self.plug()

    @property
    def plugged(self) -> bool:
        return self._listener is not None

    def plug(self) -> None:
        if self._listener is not None:
            return
        if os.path.exists(self.socket_path):
            os.unlink(self.socket_path)
        listener = socket.socket(socket.AF_UNIX, socket.SOCK_SEQPACKET)
        listener.bind(self.socket_path)
        listener.listen(8)
        listener.setblocking(False)
        self._listener = listener
        self.bus.plug(self.path, self.entries)

    def unplug(self) -> None:
        self.bus.unplug(self.path)
        listener, self._listener = self._listener, None
        for handle in self._handles:
            handle.close()
        self._handles = []
        if listener is not None:
            listener.close()
            os.unlink(self.socket_path)

    def _accept(self) -> None:
        while self._listener is not None:
            try:
                handle, _ = self._listener.accept()
            except BlockingIOError:
                return
            handle.setblocking(False)
            self._handles.append(handle)

    def send(self, report: bytes) -> None:
        """One input report to every open handle (none open: it is lost, as on hidraw)."""
        self._accept()
        for handle in list(self._handles):
            try:
                handle.send(report)
            except BlockingIOError:  # the host stopped reading: the report is dropped
                pass
            except OSError:  # the host closed its handle
                self._handles.remove(handle)
                handle.close()


class Device:
    """hid.pyx's `device` over an emulated node."""

    def __init__(self, module: HidModule):
        self._module = module
        self._sock: socket.socket | None = None
        self._descriptor = b""
        self.blocking = True  # hidapi linux/hid.c: a new handle blocks

    def open_path(self, path: bytes) -> None:
        if self._sock is not None:
            raise RuntimeError("already open")
        entry = next((e for e in self._module.listing() if e["path"].encode() == path), None)
        sock = socket.socket(socket.AF_UNIX, socket.SOCK_SEQPACKET)
        try:
            if entry is None:
                raise OSError("no such node")
            sock.connect(entry["socket"])
        except OSError:
            sock.close()
            raise OSError("open failed") from None
        self._sock = sock
        self._descriptor = bytes.fromhex(entry["report_descriptor"])
        self.blocking = True

    def close(self) -> None:
        if self._sock is not None:
            self._sock.close()
            self._sock = None

    def _require(self) -> socket.socket:
        if self._sock is None:
            raise ValueError("not open")
        return self._sock

    def set_nonblocking(self, v: int) -> int:
        self._require()
        self.blocking = not v
        return 0

    def _read_timeout(self, length: int, milliseconds: int) -> bytes | None:
        """hid_read_timeout: the report, b"" for none, None for -1."""
        sock = self._require()
        if milliseconds >= 0:
            poller = select.poll()
            poller.register(sock, select.POLLIN)
            events = poller.poll(milliseconds)
            if not events:
                return b""
            if events[0][1] & (select.POLLERR | select.POLLHUP | select.POLLNVAL):
                return None
        try:
            data = sock.recv(length)  # blocks when milliseconds is -1, like read() on the node
        except BlockingIOError:
            return b""
        except OSError:
            return None
        return data if data else None  # end of stream: the node is gone

    def read(self, max_length: int, timeout_ms: int = 0) -> list[int]:
        self._require()
        if max_length < 0:
            raise ValueError("max_length must not be negative")
        if timeout_ms > 0:
            data = self._read_timeout(max_length, timeout_ms)
        else:
            data = self._read_timeout(max_length, -1 if self.blocking else 0)
        if data is None:
            raise OSError("read error")
        return list(data)

    def write(self, buff) -> int:
        sock = self._require()
        try:
            return sock.send(bytes(buff))
        except OSError:
            return -1

    def get_report_descriptor(self) -> list[int]:
        self._require()
        return list(self._descriptor)


class HidModule:
    """hid.pyx's module surface: `enumerate()` and `device()`."""

    def __init__(self, bus_directory: str | Path):
        self.directory = Path(bus_directory)

    def listing(self) -> list[dict]:
        try:
            return json.loads((self.directory / "devices.json").read_text())
        except FileNotFoundError:
            return []

    def enumerate(self, vendor_id: int = 0, product_id: int = 0) -> list[dict]:
        keys = (
            "vendor_id",
            "product_id",
            "serial_number",
            "release_number",
            "manufacturer_string",
            "product_string",
            "usage_page",
            "usage",
            "interface_number",
            "bus_type",
        )
        return [
            {"path": e["path"].encode(), **{k: e[k] for k in keys}}
            for e in self.listing()
            if vendor_id in (0, e["vendor_id"]) and product_id in (0, e["product_id"])
        ]

    def device(self) -> Device:
        return Device(self)


def module_from_environment() -> HidModule:
    """The SASPROBE_HID_API factory: the bus SASPROBE_HID_BUS names."""
    return HidModule(os.environ[BUS_ENV])
