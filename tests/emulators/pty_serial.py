"""The device end of a serial cable: a real pty pair, so pyserial opens a real tty.

The driver opens `self.path`, a stable symlink to the pty's slave (as udev's
/dev/serial/by-id links are), and the emulator thread reads and answers on the master.
`unplug()` closes both ends (the driver's next read or write fails with EIO, as when a
USB serial adapter is pulled) and removes the link; `replug()` makes a fresh pty and
points the link at it, as re-enumeration would.
"""

from __future__ import annotations

import errno
import os
import select
import threading
import time
import tty
from pathlib import Path


class PtySerialDevice:
    def __init__(self, directory, name: str = "ttyEMU0"):
        self.path = str(Path(directory) / name)
        self._lock = threading.Lock()
        self._master = self._slave = None
        self._stop = threading.Event()
        self._inbox = b""
        self.last_host_message = None  # monotonic time of the last complete host message
        self.replies_sent = 0
        self._plug()
        self._thread = threading.Thread(target=self._run, name=f"emulator-{name}", daemon=True)
        self._thread.start()

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
            self._inbox = b""

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
            self._plug()

    def stop(self) -> None:
        self._stop.set()
        self._thread.join(timeout=2)
        self.unplug()

    # wire -----------------------------------------------------------------------------
    def send(self, data: bytes) -> None:
        with self._lock:
            if self._master is None:
                return
            try:
                os.write(self._master, data)
            except OSError as exc:  # nobody reading and the buffer is full: the bytes are lost
                if exc.errno not in (errno.EAGAIN, errno.EIO):
                    raise

    def _run(self) -> None:
        while not self._stop.is_set():
            master = self._master
            if master is None:
                time.sleep(0.002)
                continue
            try:
                ready, _, _ = select.select([master], [], [], 0.005)
                data = os.read(master, 4096) if ready else b""
            except (OSError, ValueError):  # unplugged under our feet, or the host end closed
                time.sleep(0.001)
                data = b""
            if data:
                self._inbox += data
                self._inbox = self.consume(self._inbox)
            self.idle()

    # subclasses -----------------------------------------------------------------------
    def consume(self, inbox: bytes) -> bytes:
        """Handle complete host messages at the front of `inbox`; return what is left."""
        raise NotImplementedError

    def idle(self) -> None:
        """Called every few milliseconds (watchdogs)."""
