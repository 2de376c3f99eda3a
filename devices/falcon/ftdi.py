"""An FTDI USB-serial bridge driven directly over USB (the Novint Falcon's link).

FTDI chips take "SIO" vendor control requests (FTDI application notes AN232B-04/-05,
and the request table documented in the Linux kernel's ftdi_sio.h comments):
reset/purge 0, modem control 1, flow control 2, baud divisor 3, line properties 4,
latency timer 9. Every bulk-IN packet (at most 64 bytes) starts with two modem-status
bytes that are not data; `read` strips them.
"""

from __future__ import annotations

import time

from sasprobe.devices.base import DeviceFault
from sasprobe.devices.transports import UsbTransport

VENDOR_OUT = 0x40  # host → device, vendor request, device recipient

SIO_RESET = 0
SIO_MODEM_CTRL = 1
SIO_SET_FLOW_CTRL = 2
SIO_SET_BAUD_RATE = 3
SIO_SET_DATA = 4
SIO_SET_LATENCY_TIMER = 9

RESET_SIO = 0
PURGE_RX = 1
PURGE_TX = 2

DTR_BIT, RTS_BIT = 0x01, 0x02
DTR_MASK, RTS_MASK = 0x0100, 0x0200

DATA_8N1 = 0x0008  # 8 data bits, no parity (bits 8-10 = 0), one stop bit (bits 11-12 = 0)

PACKET_SIZE = 64
STATUS_BYTES = 2

# Baud divisors: 3 MHz / divisor, with the sub-integer part in bits 14-15 (AN232B-05).
DIVISOR_9600 = 0x4138  # 312.5 → 9600 baud


def divisor_to_baud(divisor: int) -> float:
    """The baud rate an FTDI (232B-class) divisor selects; used by the emulator and logs."""
    integer = divisor & 0x3FFF
    fraction = {0: 0.0, 1: 0.5, 2: 0.25, 3: 0.125}[(divisor >> 14) & 0x3]
    if integer == 0 and fraction == 0.0:
        return 3_000_000.0
    if integer == 1 and fraction == 0.0:
        return 2_000_000.0
    return 3_000_000.0 / (integer + fraction)


class FtdiBridge:
    """SIO requests and status-stripped bulk reads on top of a UsbTransport."""

    def __init__(self, usb: UsbTransport):
        self.usb = usb
        self._pending = b""

    def _request(self, request: int, value: int, index: int = 0) -> None:
        self.usb.control(VENDOR_OUT, request, value, index, None)

    def reset(self) -> None:
        self._request(SIO_RESET, RESET_SIO)

    def purge(self) -> None:
        self._request(SIO_RESET, PURGE_RX)
        self._request(SIO_RESET, PURGE_TX)
        self._pending = b""

    def set_latency_timer(self, ms: int) -> None:
        self._request(SIO_SET_LATENCY_TIMER, ms & 0xFF)

    def set_baud_divisor(self, divisor: int) -> None:
        self._request(SIO_SET_BAUD_RATE, divisor & 0xFFFF, (divisor >> 16) & 0xFF)

    def set_line_8n1(self) -> None:
        self._request(SIO_SET_DATA, DATA_8N1)

    def set_no_flow_control(self) -> None:
        self._request(SIO_SET_FLOW_CTRL, 0, 0)

    def set_dtr(self, high: bool) -> None:
        self._request(SIO_MODEM_CTRL, DTR_MASK | (DTR_BIT if high else 0))

    def set_rts(self, high: bool) -> None:
        self._request(SIO_MODEM_CTRL, RTS_MASK | (RTS_BIT if high else 0))

    def write(self, data: bytes) -> None:
        self.usb.write(data)

    def read_some(self, max_bytes: int, timeout_s: float) -> bytes:
        """Data bytes that arrived within the timeout (status bytes removed), or b""."""
        if self._pending:
            out, self._pending = self._pending[:max_bytes], self._pending[max_bytes:]
            return out
        deadline = time.monotonic() + timeout_s
        while True:
            packet = self.usb.read(PACKET_SIZE, max(deadline - time.monotonic(), 0.001))
            if len(packet) > STATUS_BYTES:
                data = packet[STATUS_BYTES:]
                out, self._pending = data[:max_bytes], data[max_bytes:]
                return out
            if time.monotonic() >= deadline:
                return b""

    def read_exact(self, size: int, timeout_s: float) -> bytes:
        """Exactly `size` bytes, or DeviceFault when they do not arrive in time."""
        deadline = time.monotonic() + timeout_s
        buf = b""
        while len(buf) < size:
            remaining = deadline - time.monotonic()
            if remaining <= 0:
                raise DeviceFault(f"{self.usb.label}: timed out waiting for {size} bytes (got {len(buf)})")
            buf += self.read_some(size - len(buf), remaining)
        return buf
