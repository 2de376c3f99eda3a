"""What the serial arms (WoodenHaptics, Haply 2DIY) share: one command out, one reply back.

Both boards answer every command with exactly one reply and never speak unasked, and
both host libraries run a strict alternation (hfabapi `getPos()`/`setForce()`, Haply's
`device_write_torques()`/`device_read_data()`). The session keeps that alternation
under a 1 kHz loop that must never wait long:

- at most one command is ever in flight: `write_force()` sends only when the previous
  reply has been read, otherwise it just keeps the newest force for the next command.
  Two commands in flight could merge in the board's input buffer (the WoodenHaptics
  firmware refuses merged commands) and would leave the host one reply behind;
- `read()` sends when nothing is in flight, then polls for the reply as Haply's and
  hfabapi's loops do, waiting at most `read_wait_s` (a quarter period at the loop rate
  the daemon passes, so a read does not hold the tick). A reply that is later than that
  gives the last pose again while it is younger than `reuse_s` (two periods); past that
  the read waits until `reply_timeout_s` after the command went out (2.5 periods: 2.5 ms
  at 1 kHz, so it never takes the daemon's three; 10 ms when the rate is not given) and
  then raises DeviceFault (the daemon writes zero force). The command stays in flight:
  a later `read()` takes its reply when it arrives, without sending anything new;
- a reply is used only if it is fresh: it must have arrived within `stale_after_s` of
  the last time the driver looked and found nothing (a host that stalled finds an old
  reply waiting). A stale reply updates the pose used for the next force command, then
  a new command is sent and its reply is what `read()` returns;
- a reply the board flags as a refused command, a garbled frame, or more bytes than
  one reply: the driver stops sending, drops input until the line has been quiet for
  `RESYNC_QUIET_S` (one non-blocking step per `read()`, each raising DeviceFault), and
  starts again with a fresh command;
- a board silent for `silent_after_s` gets its zero command again every
  `PROBE_INTERVAL_S` (the host libraries' handshake), so it resumes when it recovers;
- a lost port (cable pulled) raises DeviceFault at once; `reconnect()` reopens it.

Opening resends the zero command every `PROBE_INTERVAL_S` until the board answers (as
hfabapi's `wait_online()` does), bounded by `handshake_timeout_s`, then drops the
answers to the extra copies. Subclasses supply the wire format.
"""

from __future__ import annotations

import abc
import threading
import time

import numpy as np
from sasprobe.devices.base import DeviceFault, DeviceOpenError, DeviceState
from sasprobe.devices.hardware import HardwareDriver, VelocityFilter, clamp_force
from sasprobe.devices.transports import SerialTransport

REPLY_PERIODS = 2.5  # how many loop periods after its command a reply may take
READ_WAIT_PERIODS = 0.25  # how long a read waits for a reply before it gives the last pose again
REUSE_PERIODS = 2.0  # how old that last pose may be
PROBE_INTERVAL_S = 0.1  # hfabapi wait_online(): one "[0,0,0]" every 100 ms until the board answers
# The boards answer within a millisecond: this much silence means nothing is left.
RESYNC_QUIET_S = 0.005
JUNK_PROBES = 5  # a board that answered this many probes with foreign bytes speaks another protocol
REOPEN_HANDSHAKE_S = 1.0  # a replugged board boots in well under a second
CLOSE_WAIT_S = 0.25  # how long close() waits for the board to take its zero command (off the loop)


def timing_options(options: dict) -> dict:
    """The driver's timing from a factory's keyword options: explicit values, else from the
    loop rate the daemon passes (`rate_hz`); the rest are ignored."""
    names = ("reply_timeout_s", "read_wait_s", "reuse_s", "stale_after_s", "handshake_timeout_s")
    timing = {k: float(options[k]) for k in names if options.get(k) is not None}
    rate = float(options.get("rate_hz") or 0.0)
    if rate > 0:
        for name, periods in (
            ("reply_timeout_s", REPLY_PERIODS),
            ("read_wait_s", READ_WAIT_PERIODS),
            ("reuse_s", REUSE_PERIODS),
        ):
            timing.setdefault(name, periods / rate)
        timing.setdefault("stale_after_s", max(0.005, 5.0 / rate))
    return timing


class ArmReply:
    """One well-formed reply. `refused`: the board says it did not take our command."""

    refused = False


class BadFrame(Exception):
    """Bytes that are not a reply of this board's protocol (the message says what they were)."""


class SerialArm(HardwareDriver):
    scheme = ""  # the --device scheme, for messages

    def __init__(
        self,
        port: str | None,
        *,
        reply_timeout_s: float = 0.010,
        read_wait_s: float = 0.001,
        reuse_s: float = 0.005,
        stale_after_s: float = 0.005,
        handshake_timeout_s: float = 3.0,
        silent_after_s: float = 0.5,
    ):
        if not port:
            raise DeviceOpenError(
                f"{self.scheme} needs a serial port: --device {self.scheme}:/dev/ttyACM0 "
                "(`sasprobe devices` lists the ports)"
            )
        self.port = port
        self.reply_timeout_s = reply_timeout_s
        self.read_wait_s = read_wait_s
        self.reuse_s = reuse_s
        self.stale_after_s = stale_after_s
        self.handshake_timeout_s = handshake_timeout_s
        self.silent_after_s = silent_after_s
        self.transport = SerialTransport(port)
        self.force = np.zeros(3)  # the force last asked for, clamped; every command renders it
        self._velocity = VelocityFilter()
        self._inbox = b""
        self._sent_at: float | None = None  # when the command in flight went out
        self._looked_at = 0.0  # the last time the reply in flight was known not to be there yet
        self._probed_at = 0.0
        self._resync_reason: str | None = None
        self._quiet_since = 0.0
        self._lost: str | None = None  # why the port is gone
        self._failing: str | None = None  # why the last read failed
        self.replies = 0
        self.rejected_frames = 0
        self.refused_commands = 0
        self.stale_replies = 0
        self.reused_states = 0
        self.resyncs = 0
        self._last: DeviceState | None = None  # the state read() returned last, and when
        self._last_at = 0.0
        # the loop's read() and reconnect() vs the watchdog's zero_force_now()
        self._port_lock = threading.Lock()

    # subclasses -----------------------------------------------------------------------
    @abc.abstractmethod
    def _handshake(self, timeout_s: float) -> None:
        """After the port opens: set the board up and take its first reply (`_probe`)."""

    @abc.abstractmethod
    def _command(self) -> bytes:
        """The command rendering `self.force` at the latest pose."""

    @abc.abstractmethod
    def _zero_command(self) -> bytes:
        """The command that asks for no force (the probe)."""

    @abc.abstractmethod
    def _split(self, inbox: bytes) -> tuple[ArmReply | None, bytes]:
        """(the first reply in `inbox`, the rest), (None, inbox) while incomplete; BadFrame
        for junk."""

    @abc.abstractmethod
    def _take(self, reply: ArmReply) -> None:
        """Learn the pose a reply reports (used for the next force command)."""

    @abc.abstractmethod
    def _state(self, t_ns: int) -> tuple[np.ndarray, np.ndarray, int]:
        """(position mm, orientation quaternion, buttons) of the pose last taken."""

    @property
    @abc.abstractmethod
    def _max_force_n(self) -> float:
        """The device's force limit (read every write: keep it cheap)."""

    def _renderable(self, force_n):
        """The part of a force the mechanism can render (all of it, unless it is planar)."""
        return force_n

    # interface ------------------------------------------------------------------------
    def open(self, handshake_timeout_s: float | None = None) -> None:
        self.transport.open()
        self._reset_session()
        try:
            self._handshake(
                self.handshake_timeout_s if handshake_timeout_s is None else handshake_timeout_s
            )
        except BaseException:
            self.transport.close()
            raise

    def close(self) -> None:
        self.force = np.zeros(3)
        if self.transport.is_open and self._lost is None:
            try:
                self._send_zero_on_close()
            except DeviceFault:
                pass
        self.transport.close()
        self._sent_at = None

    def reconnect(self) -> None:
        with self._port_lock:
            self._reconnect()

    def _reconnect(self) -> None:
        if self._lost is None and self.transport.is_open:
            # the port is fine: the session recovers by itself (late reply, resync, probing)
            if self._failing is not None:
                raise DeviceFault(self._failing)
            return
        self.close()
        try:
            self.open(handshake_timeout_s=REOPEN_HANDSHAKE_S)
        except DeviceOpenError as exc:
            raise DeviceFault(f"device still unavailable: {exc}") from None

    def read(self) -> DeviceState:
        try:
            with self._port_lock:
                state = self._read()
        except DeviceFault as exc:
            self._failing = str(exc)
            raise
        self._failing = None
        return state

    def _read(self) -> DeviceState:
        if self._lost is not None:
            raise DeviceFault(self._lost)
        if self._resync_reason is not None and not self._resync_step():
            raise DeviceFault(
                f"resynchronising with the {self.scheme} arm after {self._resync_reason}"
            )
        if self._sent_at is None:
            self._send(self._command())
        reply, fresh = self._wait_reply(self.read_wait_s)
        if reply is not None and not fresh:
            self.stale_replies += 1  # the host was away: ask again for the present pose
            self._send(self._command())
            reply, fresh = self._wait_reply(self.read_wait_s)
        if reply is None and self._sent_at is not None and self._resync_reason is None:
            if self._last is not None and time.monotonic() - self._last_at <= self.reuse_s:
                self.reused_states += 1
                # a little late: the last pose again, as Haply's and hfabapi's loops do
                return self._last
            reply, fresh = self._wait_reply(self.reply_timeout_s)
        if reply is None:
            raise DeviceFault(self._silence())
        now = time.monotonic_ns()
        position, orientation, buttons = self._state(now)
        self._last_at = time.monotonic()
        self._last = DeviceState(
            t_ns=now,
            position_mm=position,
            orientation=orientation,
            velocity_mm_s=self._velocity.update(now, position),
            buttons=buttons,
            calibrated=True,
        )
        return self._last

    def write_force(self, force_n) -> None:
        self.force = clamp_force(self._renderable(force_n), self._max_force_n)
        if self._sent_at is None and self._resync_reason is None and self._lost is None:
            self._send(self._command())

    def zero_force_now(self) -> None:
        """The daemon's watchdog while its loop is stalled: the zero command goes out now.

        The command in flight (sent before the stall) has normally been answered long
        since: its reply is taken and the zero becomes the command in flight, whose reply
        the loop's next read takes. A board that has not answered yet has not taken that
        command either: a second line would meet it in the board's buffer and both be
        refused (nothing would change), so on a line protocol the zero waits for the
        watchdog's next try; binary frames queue behind each other, so the zero goes out
        at once and the reply it draws, one too many, is dropped by resynchronising (a
        fault tick or two, force zero meanwhile).

        It runs in the watchdog's thread: while the loop is inside `read()` (descheduled
        there on a busy machine) the port and the reply in flight are the read's, so it
        only leaves zero as the force of the loop's next command and raises DeviceFault
        (the watchdog tries again at its next check)."""
        self.force = np.zeros(3)
        if not self._port_lock.acquire(blocking=False):
            raise DeviceFault(
                f"the loop is reading the {self.scheme} arm: the zero goes with its next command"
            )
        try:
            self._zero_now()
        finally:
            self._port_lock.release()

    def _zero_now(self) -> None:
        if self._lost is not None:
            return
        if self._sent_at is not None:
            self._wait_reply(0.0)  # the answer, if it has come (its pose serves the next command)
        if self._sent_at is None and (self._resync_reason is None or self._resync_step()):
            self._send(self._zero_command())
        elif self._zero_may_overlap():
            self._io(self.transport.write, self._zero_command())
            self._start_resync("the watchdog's zero command while the loop stalled")

    # handshake helpers ----------------------------------------------------------------
    def _probe(self, timeout_s: float, describe) -> ArmReply:
        """Send the zero command every PROBE_INTERVAL_S until a reply comes; drop the rest.

        `describe(junk)`: the open error's wording for bytes that are not a reply.
        """
        self._inbox = b""
        self.transport.discard_input()
        junk = b""
        start = time.monotonic()
        deadline = start + timeout_s
        while True:
            now = time.monotonic()
            if junk and now - start >= JUNK_PROBES * PROBE_INTERVAL_S:
                raise DeviceOpenError(describe(junk))
            if now >= deadline:
                raise DeviceOpenError(
                    f"{self.port} opened, but the board never answered the {self.scheme} "
                    f"handshake within {timeout_s:g} s (is it a {self.scheme} "
                    "board, with its firmware flashed?)"
                )
            if now - self._probed_at >= PROBE_INTERVAL_S:
                self.transport.write(self._zero_command())
                self._probed_at = now
            self._pump(min(deadline, self._probed_at + PROBE_INTERVAL_S) - time.monotonic())
            try:
                reply, self._inbox = self._split(self._inbox)
            except BadFrame:
                junk, self._inbox = (junk + self._inbox)[-64:], b""
                continue
            if reply is not None and not reply.refused:
                self._take(reply)
                self._drain_until_quiet(deadline)
                self._sent_at = None
                return reply

    def _drain_until_quiet(self, deadline: float, quiet_s: float = 0.02) -> None:
        """Drop the answers to extra probe copies: read until `quiet_s` of silence."""
        self._inbox = b""
        quiet_since = time.monotonic()
        while time.monotonic() - quiet_since < quiet_s and time.monotonic() < deadline + 0.5:
            if self.transport.read(4096, quiet_s):
                quiet_since = time.monotonic()

    # session helpers ------------------------------------------------------------------
    def _reset_session(self) -> None:
        self.force = np.zeros(3)
        self._velocity.reset()
        self._inbox = b""
        self._sent_at = None
        self._resync_reason = None
        self._lost = None
        self._failing = None
        self._probed_at = 0.0
        self._last = None

    def _send(self, command: bytes) -> None:
        self._io(self.transport.write, command)
        self._sent_at = self._looked_at = time.monotonic()

    def _pump(self, timeout_s: float) -> bool:
        data = self._io(self.transport.read, 4096, max(timeout_s, 0.0))
        self._inbox += data
        return bool(data)

    def _io(self, call, *args):
        try:
            return call(*args)
        except DeviceFault as exc:
            self._lost = str(exc)
            self._sent_at = None
            raise

    def _wait_reply(self, wait_s: float) -> tuple[ArmReply | None, bool]:
        """The reply to the command in flight (and whether it is fresh), waiting at most
        `wait_s` and never past the reply window; None when it has not come."""
        deadline = min(self._sent_at + self.reply_timeout_s, time.monotonic() + wait_s)
        self._pump(0.0)
        while True:
            try:
                reply, self._inbox = self._split(self._inbox)
            except BadFrame as exc:
                self.rejected_frames += 1
                self._start_resync(str(exc))
                return None, False
            now = time.monotonic()
            if reply is not None:
                fresh = now - self._looked_at <= self.stale_after_s
                self._sent_at = None
                self.replies += 1
                if reply.refused:
                    self.refused_commands += 1
                    self._start_resync("a refused command")
                    return None, False
                self._take(reply)
                if self._inbox or self._pump(0.0):
                    self.rejected_frames += 1
                    self._start_resync("bytes beyond one reply")
                    return None, False
                return reply, fresh
            self._looked_at = now
            if now >= deadline:
                return None, False
            self._pump(deadline - now)

    def _start_resync(self, reason: str) -> None:
        self.resyncs += 1
        self._resync_reason = reason
        self._inbox = b""
        self._sent_at = None
        self._quiet_since = time.monotonic()

    def _resync_step(self) -> bool:
        """Drop what arrives without waiting; True once the line has been quiet long enough."""
        if self._pump(0.0):
            self._inbox = b""
            self._quiet_since = time.monotonic()
        if time.monotonic() - self._quiet_since < RESYNC_QUIET_S:
            return False
        self._resync_reason = None
        return True

    def _silence(self) -> str:
        """The fault message for a reply that has not come; re-probes a board silent for long."""
        now = time.monotonic()
        if self._resync_reason is not None:
            return f"resynchronising with the {self.scheme} arm after {self._resync_reason}"
        if now - self._sent_at >= self.silent_after_s and now - self._probed_at >= PROBE_INTERVAL_S:
            self._probed_at = now  # the answer may come to either copy; a second one is dropped
            self._io(self.transport.write, self._zero_command())
        silent_ms = (now - self._sent_at) * 1000
        return f"no reply from the {self.scheme} arm on {self.port} for {silent_ms:.0f} ms"

    def _send_zero_on_close(self) -> None:
        """Leave the board rendering nothing; wait a moment for it to take the command."""
        deadline = time.monotonic() + CLOSE_WAIT_S
        if self._sent_at is not None and not self._zero_may_overlap():
            while self._sent_at is not None and time.monotonic() < deadline:
                self._wait_for_close()
        self.transport.write(self._zero_command())
        self._sent_at = time.monotonic()
        while self._sent_at is not None and time.monotonic() < deadline:
            self._wait_for_close()

    def _wait_for_close(self) -> None:
        self._pump(0.002)
        try:
            reply, self._inbox = self._split(self._inbox)
        except BadFrame:
            reply, self._inbox = None, b""
        if reply is not None:
            self._sent_at = None

    def _zero_may_overlap(self) -> bool:
        """Whether a zero command may go out while a reply is still due (binary frames: yes)."""
        return False
