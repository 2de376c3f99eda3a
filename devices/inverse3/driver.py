"""Haply Inverse3 (and Inverse3x, Minverse) through Haply's Inverse Service, as a HapticDevice.

The service's simulation channel answers every client message with exactly one state
update (`protocol.py`). The session keeps that alternation without ever holding the
loop on the socket:

- a reader thread owns `recv()` (websockets' sync client; a thread of ours, so each
  state is stamped with the host's monotonic clock when it arrives, and a closed
  connection is seen at once);
- at most one message is in flight: `write_force()` sends the newest force only when the
  previous message has been answered, otherwise the next one carries it. Two in flight
  would leave the host a reply behind, since replies carry no sequence number;
- `read()` waits for the reply in flight at most `read_wait_s` (a quarter period at the
  daemon's rate), then gives the last state again while the reply is younger than
  `reply_timeout_s` (2.5 periods; 10 ms without a rate). Past that the read raises
  DeviceFault: a late reply is a fault, never a stall. The daemon writes zero and the
  service idles the arm when its commands stop;
- a late reply that comes is taken as usual; one that never comes (over
  `SILENT_RECONNECT_S`) or a closed connection makes `reconnect()` open a new session in
  a background thread, so the loop never waits on a connect either.
"""

from __future__ import annotations

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
from sasprobe.devices.serial_arm import READ_WAIT_PERIODS, REPLY_PERIODS
from websockets.exceptions import ConnectionClosed, InvalidHandshake, InvalidURI
from websockets.sync.client import connect

log = logging.getLogger("sasprobe.devices.inverse3")

SILENT_RECONNECT_S = 1.0  # a reply this late: the session is given up and a new one opened
HANDSHAKE_TIMEOUT_S = 2.0
CLOSE_WAIT_S = 0.05  # how long close() waits for the reply in flight before it sends zero


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
    """One WebSocket connection to the service, and its reader thread."""

    def __init__(self, ws, url: str, session_id, device: dict, first: protocol.Reading, t_ns: int):
        self.ws, self.url, self.session_id = ws, url, session_id
        self.device_id = device["device_id"]
        config = device.get("config") if isinstance(device.get("config"), dict) else {}
        self.kind = str(config.get("type", "inverse3"))
        self.handedness = config.get("handedness")
        self.cond = threading.Condition()
        self.sent = self.replied = 0
        self.sent_at = time.monotonic()
        self.latest = (t_ns, first)
        self.lost: str | None = None
        self.thread = threading.Thread(target=self._receive, name="inverse3-reader", daemon=True)
        self.thread.start()

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
                first = protocol.reading(ws.recv(timeout=timeout_s), device["device_id"])
            except TimeoutError:
                raise DeviceOpenError(
                    f"the Inverse Service at {url} did not answer the first message"
                ) from None
            except protocol.FormatError as exc:
                raise DeviceOpenError(
                    f"{url} answered outside the Inverse Service's 3.x format ({exc})"
                ) from None
            return cls(ws, url, session_id, device, first, time.monotonic_ns())
        except (ConnectionClosed, OSError) as exc:
            ws.close()
            raise _service_missing(url, f"the connection closed: {exc}") from None
        except BaseException:
            ws.close()
            raise

    def _receive(self) -> None:
        while True:
            try:
                text = self.ws.recv()
                t_ns = time.monotonic_ns()
                reading = protocol.reading(text, self.device_id)
            except ConnectionClosed as exc:
                why = f"the Inverse Service at {self.url} closed the connection ({exc})"
            except protocol.FormatError as exc:
                why = (
                    f"the Inverse Service at {self.url} sent a "
                    f"state update outside its 3.x format ({exc})"
                )
            except Exception as exc:  # the connection broke in some other way
                why = f"the connection to the Inverse Service at {self.url} failed: {exc}"
            else:
                with self.cond:
                    self.replied += 1
                    self.latest = (t_ns, reading)
                    self.cond.notify_all()
                continue
            with self.cond:
                self.lost = why
                self.cond.notify_all()
            self.ws.close()
            return

    def in_flight(self) -> bool:
        return self.replied < self.sent

    def send(self, text: str) -> None:
        with self.cond:
            self.sent += 1
            self.sent_at = time.monotonic()
        try:
            self.ws.send(text)
        except (ConnectionClosed, OSError) as exc:
            with self.cond:
                self.lost = (
                    self.lost or f"the Inverse Service at {self.url} closed the connection ({exc})"
                )
            raise DeviceFault(self.lost) from None

    def close(self) -> None:
        self.ws.close()
        self.thread.join(timeout=1.0)


class Inverse3Device(HardwareDriver):
    def __init__(
        self,
        url: str = protocol.DEFAULT_URL,
        *,
        reply_timeout_s: float = 0.010,
        read_wait_s: float = 0.001,
        handshake_timeout_s: float = HANDSHAKE_TIMEOUT_S,
    ):
        self.url = url
        self.reply_timeout_s = reply_timeout_s
        self.read_wait_s = read_wait_s
        self.handshake_timeout_s = handshake_timeout_s
        self.force = np.zeros(3)
        self.model: InverseModel | None = None
        self._session: Session | None = None
        self._connector: threading.Thread | None = None
        self._connected: Session | None = None  # what the connector opened
        self._connect_error: str | None = None
        self.reused_states = self.late_replies = self.sessions = 0

    @property
    def info(self) -> DeviceInfo:
        s = self._session
        details = {
            "url": self.url,
            "reused_states": self.reused_states,
            "late_replies": self.late_replies,
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
                "the Inverse3 %s is not calibrated: let it self-calibrate (see "
                "docs/connect-your-arm.md)",
                session.device_id,
            )

    # lifecycle ------------------------------------------------------------------------
    def open(self) -> None:
        self._take(Session.open(self.url, self.handshake_timeout_s))

    def close(self) -> None:
        self.force = np.zeros(3)
        session, self._session = self._session, None
        if session is not None:
            with session.cond:  # let the reply in flight come, so the zero can go out
                session.cond.wait_for(
                    lambda: not session.in_flight() or session.lost is not None,
                    timeout=CLOSE_WAIT_S,
                )
            if session.lost is None and not session.in_flight():
                try:
                    session.send(protocol.force_message(session.device_id, np.zeros(3)))
                except DeviceFault:
                    pass
            session.close()
        connector = self._connector
        if connector is not None:
            connector.join(timeout=self.handshake_timeout_s + 1.0)
            self._connector = None
        if self._connected is not None:
            self._connected.close()
            self._connected = None

    def reconnect(self) -> None:
        """Give up a session that is closed or silent for SILENT_RECONNECT_S, and open a new one
        in the background; DeviceFault until it is open."""
        s = self._session
        if s is not None and s.lost is None:
            silent_s = time.monotonic() - s.sent_at
            if not s.in_flight() or silent_s <= self.reply_timeout_s:
                return  # answering: nothing to do
            # the late reply may still come; read() takes it when it does
            if silent_s <= SILENT_RECONNECT_S:
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
        with s.cond:
            if s.in_flight() and s.lost is None:
                s.cond.wait_for(
                    lambda: not s.in_flight() or s.lost is not None, timeout=self.read_wait_s
                )
            if s.lost is not None:
                raise DeviceFault(s.lost)
            t_ns, reading = s.latest
            if s.in_flight():
                late_s = time.monotonic() - s.sent_at
                if late_s > self.reply_timeout_s:
                    self.late_replies += 1
                    raise DeviceFault(
                        f"the Inverse Service has not answered for {late_s * 1000:.0f} ms"
                    )
                self.reused_states += 1
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
        if s is None or s.lost is not None or s.in_flight():
            return  # the next message carries the newest force
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
    rate, which sets the read wait and the reply timeout; default the arms' nominal rate),
    reply_timeout_s, read_wait_s."""
    url = (argument or "").strip() or protocol.DEFAULT_URL
    timing = {
        k: float(options[k])
        for k in ("reply_timeout_s", "read_wait_s")
        if options.get(k) is not None
    }
    rate = float(options.get("rate_hz") or NOMINAL_RATE_HZ)  # the serial arms' reply timing
    timing.setdefault("reply_timeout_s", REPLY_PERIODS / rate)
    timing.setdefault("read_wait_s", READ_WAIT_PERIODS / rate)
    return Inverse3Device(url, **timing)
