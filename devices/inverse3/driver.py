"""Haply Inverse3 (and Inverse3x, Minverse) through Haply's Inverse Service, as a HapticDevice.

The service's simulation channel answers every client message with exactly one state
update (`protocol.py`). No tick waits for that round trip:

- `write_force()` sends the newest force every tick, whether or not the messages before
  it have been answered, up to MAX_IN_FLIGHT unanswered (beyond that the next message
  carries the newest force). Replies carry no sequence number, but none is needed: each
  is the arm's state when the service took a message, so the newest is the one to use;
- `read()` never waits: it takes every reply that has arrived (websockets' own thread
  receives them) and returns the newest, stamped when it was taken, so a pose's
  `publish_t_ns − device_t_ns` is its age. A reply the service owes for longer than
  STALE_PERIODS loop periods (measured from the newest reply, or from the oldest message
  still unanswered when that is later) makes the read a DeviceFault: the daemon writes
  zero, which goes out behind the messages in flight, and the service idles the arm
  when its commands stop;
- a closed connection is a fault at the next read; a service silent for
  `SILENT_RECONNECT_S` with messages unanswered, or a closed connection, makes
  `reconnect()` open a new session in a background thread, so the loop never waits on a
  connect either.
"""

from __future__ import annotations

import collections
import logging
import threading
import time

import numpy as np
from sasprobe.devices.base import (
    IDENTITY_QUATERNION,
    DeviceFault,
    DeviceInfo,
    DeviceOpenError,
    DeviceState,
)
from sasprobe.devices.hardware import HardwareDriver, clamp_force
from sasprobe.devices.inverse3 import protocol
from sasprobe.devices.inverse3.models import (
    NOMINAL_RATE_HZ,
    InverseModel,
    before_open_limits,
    model_for,
)
from websockets.exceptions import ConnectionClosed, InvalidHandshake, InvalidURI
from websockets.sync.client import connect

log = logging.getLogger("sasprobe.devices.inverse3")

SILENT_RECONNECT_S = 1.0  # owed a reply this long: the session is given up and a new one opened
HANDSHAKE_TIMEOUT_S = 2.0
STALE_PERIODS = 3.0  # a reply owed for this many loop periods: the read is a fault
MAX_IN_FLIGHT = 8  # messages sent and not yet answered, at most
CLOSE_WAIT_S = 0.25  # how long close() waits for the service to answer its zero (off the loop)


def _service_missing(url: str, why: object) -> DeviceOpenError:
    return DeviceOpenError(
        f"no Inverse Service answers at {url} ({why}): start Haply's Inverse Service (Haply Hub "
        "runs it) or give its address as --device inverse3:ws://HOST:PORT"
    )


def _connect(url: str, timeout_s: float):
    """A WebSocket to the service (no pings, no compression, no proxy), or DeviceOpenError."""
    try:
        return connect(
            url,
            open_timeout=timeout_s,
            close_timeout=0.2,
            ping_interval=None,
            compression=None,
            proxy=None,
            legacy=True,
        )
    except (OSError, TimeoutError, InvalidHandshake) as exc:
        raise _service_missing(url, exc) from None
    except InvalidURI as exc:
        raise DeviceOpenError(f"inverse3:{url}: not a WebSocket address ({exc})") from None


class Session:
    """One WebSocket connection to the service: what was sent, what came back."""

    def __init__(self, ws, url: str, session_id, device: dict, first: str, t_ns: int):
        self.ws, self.url, self.session_id = ws, url, session_id
        self.device_id = device["device_id"]
        config = device.get("config") if isinstance(device.get("config"), dict) else {}
        self.kind = str(config.get("type", "inverse3"))
        self.handedness = config.get("handedness")
        self.sent = self.replied = 1  # the first message and its answer
        self.unanswered: collections.deque[int] = collections.deque()  # when each was sent, ns
        self.latest = (t_ns, protocol.reading(first, self.device_id))  # newest state, when taken
        self.lost: str | None = None

    @classmethod
    def open(cls, url: str, timeout_s: float) -> Session:
        """Connect, take the inventory, send the first message and take its answer."""
        ws = _connect(url, timeout_s)
        try:
            try:
                session_id, devices = protocol.inventory(ws.recv(timeout=timeout_s))
            except TimeoutError:
                raise DeviceOpenError(
                    f"{url} accepted a WebSocket but sent no inventory within {timeout_s:g} s: "
                    "is it the Inverse Service's 3.x channel (port 10001)?"
                ) from None
            except protocol.FormatError as exc:
                raise DeviceOpenError(
                    f"{url} does not speak the Inverse Service's 3.x format ({exc}): is it the "
                    "legacy 3.0 channel, or another server?"
                ) from None
            if not devices:
                raise DeviceOpenError(
                    f"the Inverse Service at {url} lists no Inverse3: is the arm plugged in and "
                    "powered, and shown in Haply Hub?"
                )
            device = devices[0]
            ws.send(protocol.first_message(device["device_id"]))
            try:
                first = ws.recv(timeout=timeout_s)
                return cls(ws, url, session_id, device, first, time.monotonic_ns())
            except TimeoutError:
                raise DeviceOpenError(
                    f"the Inverse Service at {url} did not answer the first message"
                ) from None
            except protocol.FormatError as exc:
                raise DeviceOpenError(
                    f"{url} answered outside the Inverse Service's 3.x format ({exc})"
                ) from None
        except (ConnectionClosed, OSError) as exc:
            ws.close()
            raise _service_missing(url, f"the connection closed: {exc}") from None
        except BaseException:
            ws.close()
            raise

    def take_replies(self) -> None:
        """Take every reply that has arrived, keeping the newest state; never waits."""
        newest = None
        try:
            while self.lost is None:
                newest = self.ws.recv(timeout=0)
                self.replied += 1
                if self.unanswered:
                    self.unanswered.popleft()
        except TimeoutError:
            pass
        except ConnectionClosed as exc:
            self.lost = f"the Inverse Service at {self.url} closed the connection ({exc})"
        if newest is None:
            return
        try:
            self.latest = (time.monotonic_ns(), protocol.reading(newest, self.device_id))
        except protocol.FormatError as exc:
            self.lost = (
                f"the Inverse Service at {self.url} sent a state update outside its 3.x "
                f"format ({exc})"
            )

    def owed_since_ns(self) -> int | None:
        """Since when a reply has been owed (the newest reply, or the oldest message still
        unanswered when that is later); None when every message has been answered."""
        return max(self.unanswered[0], self.latest[0]) if self.unanswered else None

    def send(self, text: str) -> None:
        self.sent += 1
        self.unanswered.append(time.monotonic_ns())
        try:
            self.ws.send(text)
        except (ConnectionClosed, OSError) as exc:
            self.lost = (
                self.lost or f"the Inverse Service at {self.url} closed the connection ({exc})"
            )
            raise DeviceFault(self.lost) from None

    def close(self) -> None:
        self.ws.close()


class Inverse3Device(HardwareDriver):
    def __init__(
        self,
        url: str = protocol.DEFAULT_URL,
        *,
        stale_after_s: float = STALE_PERIODS / NOMINAL_RATE_HZ,
        handshake_timeout_s: float = HANDSHAKE_TIMEOUT_S,
    ):
        self.url = url
        self.stale_after_s = stale_after_s
        self.handshake_timeout_s = handshake_timeout_s
        self.force = np.zeros(3)
        self.model: InverseModel | None = None
        self._session: Session | None = None
        self._connector: threading.Thread | None = None
        self._connected: Session | None = None  # what the connector opened
        self._connect_error: str | None = None
        self.reused_states = self.stale_reads = self.held_commands = self.sessions = 0

    @property
    def info(self) -> DeviceInfo:
        s = self._session
        details = {
            "url": self.url,
            "reused_states": self.reused_states,
            "stale_reads": self.stale_reads,
            "held_commands": self.held_commands,
            "sessions": self.sessions,
        }
        if s is not None:
            details.update(
                session_id=s.session_id,
                device_id=s.device_id,
                type=s.kind,
                handedness=s.handedness,
                messages_sent=s.sent,
                replies=s.replied,
            )
        model = self.model
        return DeviceInfo(
            kind="inverse3",
            model=model.name if model else "Haply Inverse3 (not connected yet)",
            limits=model.limits if model else before_open_limits(),
            serial=str(s.device_id) if s else "",
            details=details,
        )

    def _take(self, session: Session) -> None:
        self._session = session
        self.model = model_for(session.kind)
        self.sessions += 1
        if not session.latest[1].calibrated:
            log.warning(
                "the Inverse3 %s is not calibrated: let it self-calibrate "
                "(see docs/connect-your-arm.md)",
                session.device_id,
            )

    # lifecycle ------------------------------------------------------------------------
    def open(self) -> None:
        self._take(Session.open(self.url, self.handshake_timeout_s))

    def close(self) -> None:
        """Zero force behind whatever is in flight; end the session once the service has
        answered it (a connection closed with messages unread may lose them), or after
        CLOSE_WAIT_S."""
        self.force = np.zeros(3)
        session, self._session = self._session, None
        if session is not None:
            if session.lost is None:
                try:
                    session.send(protocol.force_message(session.device_id, np.zeros(3)))
                except DeviceFault:
                    pass
                deadline = time.monotonic() + CLOSE_WAIT_S
                while session.unanswered and session.lost is None:
                    session.take_replies()
                    if time.monotonic() > deadline:
                        break
                    time.sleep(0.001)
            session.close()
        connector = self._connector
        if connector is not None:
            connector.join(timeout=self.handshake_timeout_s + 1.0)
            self._connector = None
        if self._connected is not None:
            self._connected.close()
            self._connected = None

    def reconnect(self) -> None:
        """Give up a session that is closed or owes a reply for SILENT_RECONNECT_S, and open a
        new one in the background; DeviceFault until it is open."""
        s = self._session
        if s is not None and s.lost is None:
            s.take_replies()
            owed = s.owed_since_ns()
            silent_s = 0.0 if owed is None else (time.monotonic_ns() - owed) / 1e9
            if silent_s <= self.stale_after_s:
                return  # answering: nothing to do
            if silent_s <= SILENT_RECONNECT_S:  # the late reply may still come
                raise DeviceFault(
                    f"the Inverse Service has not answered for {silent_s * 1000:.0f} ms"
                )
            log.warning(
                "the Inverse Service has not answered for %.1f s: opening a new session", silent_s
            )
            s.close()
        if self._connected is not None:
            if s is not None:
                s.close()
            self._take(self._connected)
            self._connected = None
            return
        if self._connector is None or not self._connector.is_alive():
            why, self._connect_error = self._connect_error, None
            self._connector = threading.Thread(
                target=self._connect, name="inverse3-connect", daemon=True
            )
            self._connector.start()
            if why:
                raise DeviceFault(f"device still unavailable: {why}")
        raise DeviceFault(f"reconnecting to the Inverse Service at {self.url}")

    def _connect(self) -> None:
        try:
            self._connected = Session.open(self.url, self.handshake_timeout_s)
        except DeviceOpenError as exc:
            self._connect_error = str(exc)

    # interface ------------------------------------------------------------------------
    def read(self) -> DeviceState:
        s = self._session
        if s is None:
            raise DeviceFault(f"not connected to the Inverse Service at {self.url}")
        replied = s.replied
        s.take_replies()
        if s.lost is not None:
            raise DeviceFault(s.lost)
        owed = s.owed_since_ns()
        if owed is not None and time.monotonic_ns() - owed > self.stale_after_s * 1e9:
            self.stale_reads += 1
            raise DeviceFault(
                f"the Inverse Service has not answered for "
                f"{(time.monotonic_ns() - owed) / 1e6:.1f} ms"
            )
        if s.replied == replied:
            self.reused_states += 1
        t_ns, reading = s.latest
        return DeviceState(
            t_ns=t_ns,
            position_mm=reading.position_mm.copy(),
            orientation=(
                reading.orientation
                if reading.orientation is not None
                else np.array(IDENTITY_QUATERNION)
            ),
            velocity_mm_s=reading.velocity_mm_s.copy(),
            buttons=reading.buttons,
            calibrated=reading.calibrated,
        )

    def write_force(self, force_n) -> None:
        limit = (self.model.limits if self.model is not None else before_open_limits()).max_force_n
        self.force = clamp_force(force_n, limit)
        s = self._session
        if s is None or s.lost is not None:
            return
        if len(s.unanswered) >= MAX_IN_FLIGHT:
            self.held_commands += 1  # the next message carries the newest force
            return
        calibrated = s.latest[1].calibrated  # an uncalibrated arm gets zero, whatever is asked
        s.send(protocol.force_message(s.device_id, self.force if calibrated else np.zeros(3)))


def list_arms(url: str, timeout_s: float = HANDSHAKE_TIMEOUT_S) -> list[dict]:
    """The Inverse3 arms an Inverse Service lists in its inventory: {device_id, model,
    calibrated}; DeviceOpenError when nothing answers at `url` or it speaks another format.
    Nothing is sent: the session ends unused."""
    ws = _connect(url, timeout_s)
    try:
        _session_id, devices = protocol.inventory(ws.recv(timeout=timeout_s))
    except (TimeoutError, ConnectionClosed, protocol.FormatError) as exc:
        raise DeviceOpenError(
            f"{url} answers, but not as the Inverse Service's 3.x channel ({exc})"
        ) from None
    finally:
        ws.close()
    arms = []
    for entry in devices:
        config = entry.get("config") if isinstance(entry.get("config"), dict) else {}
        status = entry.get("status") if isinstance(entry.get("status"), dict) else {}
        arms.append(
            {
                "device_id": entry["device_id"],
                "model": model_for(str(config.get("type", "inverse3"))).name,
                "calibrated": bool(status.get("calibrated", True)),
            }
        )
    return arms


def create(argument: str | None = None, **options) -> Inverse3Device:
    """`inverse3[:URL]` (default ws://localhost:10001). Options: rate_hz (the daemon's loop
    rate, which sets how long a reply may be owed: STALE_PERIODS periods; default the arms'
    nominal rate), stale_after_s."""
    url = (argument or "").strip() or protocol.DEFAULT_URL
    rate = float(options.get("rate_hz") or NOMINAL_RATE_HZ)
    stale = options.get("stale_after_s")
    return Inverse3Device(url, stale_after_s=float(stale) if stale else STALE_PERIODS / rate)
