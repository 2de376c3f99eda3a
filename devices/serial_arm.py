"""What the serial arms (WoodenHaptics, Haply 2DIY) share: one command out, one reply back.

The host runs the control loop. `read()` sends the latest command unless `write_force()`
already did, then waits for the reply; `write_force()` turns a force into the arm's
command and sends it, so the reply to it is what the next `read()` returns. A reply
that does not arrive within the read timeout raises DeviceFault; malformed replies are
counted in `rejected_frames` and skipped.
"""

from __future__ import annotations

import abc
import time

import numpy as np

from sasprobe.devices.base import DeviceFault, DeviceOpenError, DeviceState
from sasprobe.devices.support import HardwareDevice, VelocityFilter
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
        self._awaiting_reply = False
        self._last_sent = 0.0

    # subclasses -----------------------------------------------------------------------
    @abc.abstractmethod
    def _handshake(self) -> None:
        """After the port opens: set the arm up and read its first reply."""

    @abc.abstractmethod
    def _command_bytes(self) -> bytes:
        """The current command (the force last asked for, or zero) on the wire."""

    @abc.abstractmethod
    def _receive(self, deadline: float):
        """One valid reply (parsed), or None when the deadline passed; counts rejects."""

    @abc.abstractmethod
    def _state_from(self, reply, t_ns: int) -> tuple[np.ndarray, np.ndarray, int, bool]:
        """(position mm, orientation quaternion, buttons, calibrated) of a reply."""

    @abc.abstractmethod
    def _set_force(self, force_n) -> None:
        """Turn a device-frame force into the next command (zero while uncalibrated)."""

    # interface ------------------------------------------------------------------------
    def open(self) -> None:
        self.transport.open()
        self._awaiting_reply = False
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
        if self.transport.is_open:
            try:
                self._set_force(np.zeros(3))
                self._send()
            except DeviceFault:
                pass
        self.transport.close()
        self._awaiting_reply = False

    def read(self) -> DeviceState:
        if not self._awaiting_reply:
            self._send()
        self._awaiting_reply = False
        reply = self._receive_or_fault()
        now = time.monotonic_ns()
        position, orientation, buttons, calibrated = self._state_from(reply, now)
        return DeviceState(t_ns=now, position_mm=position, orientation=orientation,
                           velocity_mm_s=self._velocity.update(now, position), buttons=buttons,
                           calibrated=calibrated)

    def write_force(self, force_n) -> None:
        self._set_force(force_n)
        self._send()

    # helpers --------------------------------------------------------------------------
    def _send(self) -> None:
        self.transport.write(self._command_bytes())
        self._last_sent = time.monotonic()
        self._awaiting_reply = True

    def _receive_or_fault(self):
        reply = self._receive(time.monotonic() + self.read_timeout_s)
        if reply is None:
            raise DeviceFault(f"{self.scheme} arm on {self.port} did not answer within "
                              f"{self.read_timeout_s * 1000:.0f} ms")
        return reply
