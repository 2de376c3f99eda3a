"""What the serial arms (WoodenHaptics, Haply 2DIY) share: one command out, one reply back.

The host runs the control loop. `read()` sends the latest command unless `write_force()`
already did, then waits for the reply; `write_force()` turns a force into the arm's
command and sends it, so the reply to it is what the next `read()` returns (when several
commands went out since the last read, `read()` collects every reply and returns the
newest, so replies never lag). A reply that does not arrive within the read timeout
raises DeviceFault; malformed replies are counted in `rejected_frames` and skipped.
"""

from __future__ import annotations

import abc
import time

import numpy as np

from sasprobe.devices.base import DeviceFault, DeviceOpenError, DeviceState
from sasprobe.devices.support import HardwareDevice, VelocityFilter, clamp_force
from sasprobe.devices.transports import SerialTransport


class SerialArm(HardwareDevice):
    scheme = ""  # the --device scheme, for messages

    def __init__(self, port: str | None, *, baudrate: int = 115200, read_timeout_s: float = 0.05):
        if not port:
            raise DeviceOpenError(f"{self.scheme} needs a serial port: --device {self.scheme}:/dev/ttyACM0 "
                                  "(`sasprobe devices` lists the ports)")
        self.port = port
        self.read_timeout_s = read_timeout_s
        self.transport = SerialTransport(port, baudrate)
        self.rejected_frames = 0
        self._velocity = VelocityFilter()
        self.force = np.zeros(3)  # the force last asked for, clamped; every command renders it
        self._outstanding = 0  # commands sent whose replies have not been read
        self._replies_after_this = 0  # while read() collects: replies still due after this one
        self._last_sent = 0.0

    # subclasses -----------------------------------------------------------------------
    @abc.abstractmethod
    def _handshake(self) -> None:
        """After the port opens: set the arm up and read its first reply."""

    @abc.abstractmethod
    def _command_bytes(self) -> bytes:
        """The command rendering `self.force` at the latest pose (zero while uncalibrated)."""

    @abc.abstractmethod
    def _receive(self, deadline: float):
        """One valid reply (parsed), or None when the deadline passed; counts rejects."""

    @abc.abstractmethod
    def _state_from(self, reply, t_ns: int) -> tuple[np.ndarray, np.ndarray, int, bool]:
        """(position mm, orientation quaternion, buttons, calibrated) of a reply."""

    # interface ------------------------------------------------------------------------
    def open(self) -> None:
        self.transport.open()
        self._outstanding = 0
        self.force = np.zeros(3)
        self._velocity.reset()
        try:
            self._handshake()
        except DeviceFault as exc:
            self.transport.close()
            raise DeviceOpenError(f"{self.port} opened but the arm did not answer like a {self.scheme} arm: {exc}") \
                from None
        except BaseException:
            self.transport.close()
            raise

    def close(self) -> None:
        self.force = np.zeros(3)
        if self.transport.is_open:
            try:
                self._send()
            except DeviceFault:
                pass
        self.transport.close()
        self._outstanding = 0

    def read(self) -> DeviceState:
        if self._outstanding == 0:
            self._send()
        pending, self._outstanding = self._outstanding, 0
        for i in range(pending):
            self._replies_after_this = pending - 1 - i
            reply = self._receive_or_fault()
        now = time.monotonic_ns()
        position, orientation, buttons, calibrated = self._state_from(reply, now)
        return DeviceState(t_ns=now, position_mm=position, orientation=orientation,
                           velocity_mm_s=self._velocity.update(now, position), buttons=buttons,
                           calibrated=calibrated)

    def write_force(self, force_n) -> None:
        self.force = clamp_force(force_n, self.info.limits.max_force_n)
        self._send()

    # helpers --------------------------------------------------------------------------
    def _send(self) -> None:
        self._write_command()
        self._outstanding += 1

    def _write_command(self) -> None:
        self.transport.write(self._command_bytes())
        self._last_sent = time.monotonic()

    def _receive_or_fault(self):
        reply = self._receive(time.monotonic() + self.read_timeout_s)
        if reply is None:
            raise DeviceFault(f"{self.scheme} arm on {self.port} did not answer within "
                              f"{self.read_timeout_s * 1000:.0f} ms")
        return reply
