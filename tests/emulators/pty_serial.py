"""The device end of a USB serial cable: a real pty pair and a firmware thread that runs on it.

The driver opens `self.path`, a stable symlink to the pty's slave (as udev's
/dev/serial/by-id links are). The emulated firmware runs its own `loop()` over and over
in a thread, reading and writing through the small Arduino-like serial API below
(`available`, `read` → a byte or −1, `read_bytes` with a timeout, `write`), so its
parsing sees bytes exactly as a board's does: as they arrive, merged or split.

Faults a test can cause: `inject(data)` (bytes nobody asked for), `stall(seconds)`
(the firmware stops reading and answering for a while; the host's bytes pile up in the
buffer as they would in the USB stack), `go_silent()` (it stops reading and answering
until `resume()`), `unplug()` / `replug()` (the cable: the driver's next read or write
fails with EIO; replugging makes a fresh pty, and the firmware restarts from
`power_on()`, as a USB-powered board does).

A board's UART never waits for the host's scheduler; this thread does. Where the system
allows it (root, CAP_SYS_NICE or an rtprio limit) the thread takes the lowest real-time
priority, so that other processes on a busy machine do not starve it (a 250 Hz
WoodenHaptics press with two busy loops beside it faulted on late replies in 26-37 % of
its ticks at the normal priority, 0.5 % at this one); the daemon's loop keeps its higher
one.
`longest_deaf_s` is the longest the port went unread outside the faults above (the test
machine starved the thread all the same), so a test can tell the emulator's hiccups from
the driver's.
"""

from __future__ import annotations

import errno
import os
import select
import threading
import time
import tty
from pathlib import Path

FIRMWARE_PRIORITY = 1  # SCHED_FIFO: above every normal thread, below the daemon's loop


class Unplugged(Exception):
    """Raised inside the firmware thread when the cable is out."""


class PtySerialDevice:
    def __init__(self, directory, name: str = "ttyEMU0"):
        self.path = str(Path(directory) / name)
        self._lock = threading.Lock()
        self._master = self._slave = None
        self._stop = threading.Event()
        self._rx = bytearray()  # bytes the firmware has not read yet
        self._stall_until = 0.0
        self.silent = False
        self.replies_sent = 0
        self.longest_deaf_s = 0.0
        self._looked_at: float | None = None  # when the port was last read; None across a fault
        self._plug()
        self.power_on()
        self._thread = threading.Thread(target=self._run, name=f"firmware-{name}", daemon=True)
        self._thread.start()

    # subclasses -----------------------------------------------------------------------
    def power_on(self) -> None:
        """The firmware's setup(): state after power-up."""

    def loop(self) -> None:
        """One pass of the firmware's loop()."""
        raise NotImplementedError

    def tick(self) -> None:
        """Interrupt-driven work (timers, the physics of the arm), run about every millisecond."""

    # cable ----------------------------------------------------------------------------
    def _plug(self) -> None:
        master, slave = os.openpty()
        tty.setraw(slave)  # no echo or line editing before the driver configures the port
        os.set_blocking(master, False)
        tmp = self.path + ".new"
        if os.path.lexists(tmp):
            os.unlink(tmp)
        os.symlink(os.ttyname(slave), tmp)
        os.replace(tmp, self.path)
        with self._lock:
            self._master, self._slave = master, slave
            self._rx = bytearray()

    @property
    def plugged(self) -> bool:
        return self._master is not None

    def unplug(self) -> None:
        with self._lock:
            master, slave = self._master, self._slave
            self._master = self._slave = None
        if os.path.lexists(self.path):
            os.unlink(self.path)
        for fd in (master, slave):
            if fd is not None:
                os.close(fd)

    def replug(self) -> None:
        if not self.plugged:
            self.power_on()
            self._plug()

    @property
    def running(self) -> bool:
        """Whether the firmware thread is still running (it ends on stop() or an exception)."""
        return self._thread.is_alive()

    def stop(self) -> None:
        self._stop.set()
        self._thread.join(timeout=2)
        self.unplug()

    # faults -----------------------------------------------------------------------------
    def stall(self, seconds: float) -> None:
        self._stall_until = time.monotonic() + seconds

    def go_silent(self) -> None:
        self.silent = True

    def resume(self) -> None:
        self.silent = False

    def inject(self, data: bytes) -> None:
        """Bytes on the line that no command asked for (a glitch, another program's output)."""
        with self._lock:
            if self._master is not None:
                os.write(self._master, data)

    # the firmware's serial port -------------------------------------------------------
    def _run(self) -> None:
        try:
            os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(FIRMWARE_PRIORITY))
        except (OSError, AttributeError):  # not allowed (or not Linux): the normal priority
            pass
        while not self._stop.is_set():
            try:
                if self.silent or not self.plugged:
                    self._idle(0.002)
                    continue
                self.loop()
            except Unplugged:
                self._idle(0.002)

    def _idle(self, seconds: float) -> None:
        self._looked_at = None  # a fault (stall, silence, cable) is deaf on purpose
        end = time.monotonic() + seconds
        while time.monotonic() < end and not self._stop.is_set():
            self.tick()
            time.sleep(min(0.001, max(end - time.monotonic(), 0.0)))

    def _honour_stall(self) -> None:
        while time.monotonic() < self._stall_until or self.silent:
            if self._stop.is_set() or not self.plugged:
                raise Unplugged
            self._idle(0.001)

    def _fill(self, timeout_s: float) -> None:
        """Move what the host sent into the receive buffer, waiting up to `timeout_s`."""
        self._honour_stall()
        master = self._master
        if master is None or self._stop.is_set():
            raise Unplugged
        try:
            ready, _, _ = select.select([master], [], [], max(timeout_s, 0.0))
            if ready:
                self._rx += os.read(master, 4096)
        except (OSError, ValueError):  # unplugged under our feet, or the host end closed
            if not self.plugged:
                raise Unplugged from None
            time.sleep(0.001)
        looked_at = time.monotonic()
        if self._looked_at is not None:  # beyond the wait asked for: the thread was not running
            self.longest_deaf_s = max(
                self.longest_deaf_s, looked_at - self._looked_at - max(timeout_s, 0.0)
            )
        self._looked_at = looked_at

    def available(self) -> int:
        if not self._rx:
            self._fill(0.0)
        return len(self._rx)

    def read(self) -> int:
        """One byte, or −1 when none is waiting (Arduino `Serial.read()`)."""
        if not self.available():
            return -1
        byte = self._rx[0]
        del self._rx[0]
        return byte

    def wait_byte(self) -> int:
        """Block until a byte comes (a firmware spinning on `available()`), running the timers."""
        while not self._rx:
            self.tick()
            self._fill(0.001)
        return self.read()

    def read_bytes(self, count: int, timeout_s: float = 1.0) -> bytes:
        """Up to `count` bytes, waiting at most `timeout_s` for them (Arduino `readBytes()`)."""
        deadline = time.monotonic() + timeout_s
        while len(self._rx) < count and time.monotonic() < deadline:
            self.tick()
            self._fill(min(0.001, max(deadline - time.monotonic(), 0.0)))
        out = bytes(self._rx[:count])
        del self._rx[:count]
        return out

    def write(self, data: bytes) -> None:
        with self._lock:
            if self._master is None:
                raise Unplugged
            try:
                os.write(self._master, data)
            except OSError as exc:  # nobody reading and the buffer is full: the bytes are lost
                if exc.errno not in (errno.EAGAIN, errno.EIO):
                    raise
        self.replies_sent += 1


class Rig:
    """What a serial emulator's `launch()` returns: the board, its `--device` string, the
    hand that holds the stylus, and `close()` (stops the board, removes a scratch folder)."""

    def __init__(self, board: PtySerialDevice, device_spec: str, directory=None):
        self.board = board
        self.device_spec = device_spec
        self.env: dict[str, str] = {}
        self.hand = board.hand
        self._directory = directory

    def close(self) -> None:
        self.board.stop()
        if self._directory is not None:
            self._directory.cleanup()
