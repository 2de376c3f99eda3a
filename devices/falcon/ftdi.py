"""The Falcon's FTDI USB-serial bridge, driven over raw USB as libnifalcon's libusb core does.

Control requests (FalconCommLibUSB.cpp, from libftdi's table): reset/purge 0, modem
control 1, flow control 2, baud divisor 3, line properties 4, latency timer 9, all
vendor-type (0x40) to interface 0. Every bulk-IN packet starts with two modem-status
bytes, which are not data.

Two ways of moving bytes:
- blocking (`write_blocking`, `read_packet`): the loader handshake and the upload,
  libnifalcon's readBlocking/writeBlocking;
- asynchronous (`start`/`send`/`take`): normal mode. libnifalcon submits libusb
  transfers and polls them; pyusb has only synchronous transfers, so a reader thread
  keeps one 64-byte IN transfer pending and a writer thread sends the newest frame
  handed to it. The control loop never waits on USB.
"""

from __future__ import annotations

import threading
import time

from sasprobe.devices.base import DeviceFault
from sasprobe.devices.transports import TransferTimeout, UsbTransport

VENDOR_OUT = 0x40

SIO_RESET = 0
SIO_MODEM_CTRL = 1
SIO_SET_FLOW_CTRL = 2
SIO_SET_BAUD_RATE = 3
SIO_SET_DATA = 4
SIO_SET_LATENCY_TIMER = 9

PURGE_RX, PURGE_TX = 1, 2
DTR_HIGH, DTR_LOW = 0x0101, 0x0100  # value | mask << 8
RTS_LOW = 0x0200
DATA_8N1 = 0x0008  # 8 data bits, no parity, one stop bit

DIVISOR_9600 = 0x4138  # the loader's probe rate
DIVISOR_LOADER = 0x15  # the upload rate (≈ 140 kbaud, libnifalcon's comment)
DIVISOR_NORMAL = 0x2  # normal mode
LATENCY_LOADER_MS, LATENCY_NORMAL_MS = 16, 1

PACKET_SIZE = 64
STATUS_BYTES = 2
READ_WAIT_S = 0.1  # the reader thread's transfer timeout: how soon it notices a stop


class FtdiLink:
    """SIO requests, blocking packet I/O and the asynchronous normal-mode I/O of one Falcon."""

    def __init__(self, usb: UsbTransport):
        self.usb = usb
        self._lock = threading.Lock()
        self._wake = threading.Condition(self._lock)
        self._threads: list[threading.Thread] = []
        self._running = False
        self._received = bytearray()
        self._received_ns = 0
        self._outgoing: bytes | None = None
        self.error: str | None = None  # set by an I/O thread when the USB link fails

    # -- control requests --------------------------------------------------------------
    def request(self, request: int, value: int, index: int = 0) -> None:
        self.usb.control(VENDOR_OUT, request, value, index, None, timeout_s=1.0)

    def purge(self) -> None:
        self.request(SIO_RESET, PURGE_RX)
        self.request(SIO_RESET, PURGE_TX)

    def normal_mode(self) -> None:
        """FalconCommLibUSB::setNormalMode: latency 1 ms, divisor 0x2, purge."""
        self.request(SIO_SET_LATENCY_TIMER, LATENCY_NORMAL_MS)
        self.request(SIO_SET_BAUD_RATE, DIVISOR_NORMAL)
        self.purge()

    # -- blocking I/O (the loader) -----------------------------------------------------
    def write_blocking(self, data: bytes, timeout_s: float = 1.0) -> None:
        self.usb.write(data, timeout_s)

    def read_packet(self, timeout_s: float) -> bytes:
        """The data of the next IN packet (status bytes removed); b"" if none in time."""
        return self.usb.read(PACKET_SIZE, timeout_s)[STATUS_BYTES:]

    # -- asynchronous I/O (normal mode) ------------------------------------------------
    def start(self) -> None:
        if self._running:
            return
        self._running, self.error = True, None
        self._received.clear()
        self._outgoing = None
        self._threads = [
            threading.Thread(target=loop, name=f"falcon-{loop.__name__}", daemon=True)
            for loop in (self._reader, self._writer)
        ]
        for thread in self._threads:
            thread.start()

    def stop(self) -> None:
        with self._lock:
            self._running = False
            self._wake.notify_all()
        for thread in self._threads:
            thread.join(timeout=2.0)
        self._threads = []

    def send(self, frame: bytes) -> None:
        """Hand a frame to the writer thread; one not yet sent is replaced (it is owed no reply)."""
        with self._lock:
            self._outgoing = frame
            self._wake.notify()

    def take(self) -> tuple[bytes, int]:
        """(bytes received since the last take, monotonic ns when the newest arrived)."""
        with self._lock:
            data = bytes(self._received)
            self._received.clear()
            return data, self._received_ns

    def _fail(self, exc: DeviceFault) -> None:
        with self._lock:
            if self.error is None:
                self.error = str(exc)
            self._running = False
            self._wake.notify_all()

    def _reader(self) -> None:
        while self._running:
            try:
                data = self.read_packet(READ_WAIT_S)
            except DeviceFault as exc:
                self._fail(exc)
                return
            if data:
                now = time.monotonic_ns()
                with self._lock:
                    self._received += data
                    self._received_ns = now

    def _writer(self) -> None:
        while True:
            with self._lock:
                while self._running and self._outgoing is None:
                    self._wake.wait()
                if not self._running:
                    return
                frame, self._outgoing = self._outgoing, None
            try:
                self.usb.write(frame)
            # the chip's buffer is full: the frame is lost, the driver resends
            except TransferTimeout:
                continue
            except DeviceFault as exc:
                self._fail(exc)
                return
