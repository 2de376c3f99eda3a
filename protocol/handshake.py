"""Why a client hears nothing: its socket's connection events, turned into one line.

ZeroMQ hides connection trouble: a client whose CURVE key is refused, or who has the
wrong server key, or none, simply receives nothing, exactly like a client whose daemon
is not running. A `ConnectionWatch` keeps a socket monitor on the client's socket and,
when the client gives up waiting, says which of these it was (libzmq's events: a
refused key is HANDSHAKE_FAILED_AUTH, a missing or unexpected key a mechanism mismatch,
a wrong server key a handshake that fails without detail, a missing daemon only
connection retries, a daemon that went away a disconnection after the handshake).
`start_monitor` and `stop_monitor` start and end any socket's monitor (the daemon's too) in
the ways libzmq allows.
"""

from __future__ import annotations

import itertools

import zmq
from zmq.utils.monitor import recv_monitor_message

_EVENTS = (
    zmq.EVENT_CONNECTED
    | zmq.EVENT_CONNECT_RETRIED
    | zmq.EVENT_DISCONNECTED
    | zmq.EVENT_HANDSHAKE_SUCCEEDED
    | zmq.EVENT_HANDSHAKE_FAILED_NO_DETAIL
    | zmq.EVENT_HANDSHAKE_FAILED_PROTOCOL
    | zmq.EVENT_HANDSHAKE_FAILED_AUTH
)
_MECHANISM_MISMATCH = 0x11000002  # ZMQ_PROTOCOL_ERROR_ZMTP_MECHANISM_MISMATCH
_MONITOR_IDS = itertools.count(1)


def start_monitor(socket: zmq.Socket, events: int) -> zmq.Socket:
    """A PAIR socket receiving `socket`'s `events`; close both with `stop_monitor`.

    Its address is this process's own next one: pyzmq's default names the monitor after the
    socket's descriptor, which a new socket reuses as soon as the old one closes, while
    libzmq may still hold the old monitor's address (for good, when the socket closed with
    its monitor running): the new socket's monitor then failed with EADDRINUSE.
    """
    return socket.get_monitor_socket(events, addr=f"inproc://sasprobe.monitor.{next(_MONITOR_IDS)}")


def stop_monitor(socket: zmq.Socket, monitor: zmq.Socket) -> None:
    """Stop `socket`'s monitor, then close its reader `monitor`; call it before closing
    `socket`. The order is libzmq's (4.3.5): a socket closed while its monitor runs is kept,
    with its monitor and their pipe, for good (three sockets and descriptors of the context
    each time, until the context can make none), and stopping a monitor whose reader is
    closed already can block."""
    if not monitor.closed:
        try:
            socket.disable_monitor()
        except zmq.ZMQError:  # the socket is closed already
            pass
    monitor.close(linger=0)


class ConnectionWatch:
    def __init__(
        self, socket: zmq.Socket, endpoint: str, with_keys: bool, local_keys: bool = False
    ) -> None:
        self.endpoint = endpoint
        self.with_keys = with_keys
        self.local_keys = local_keys  # the keys are this user's local ones (no --keys was given)
        self._socket = socket
        self._monitor = start_monitor(socket, _EVENTS)
        self._seen: dict[int, int] = {}  # event -> its last value
        self._link: int | None = None  # the newest of CONNECTED, HANDSHAKE_SUCCEEDED, DISCONNECTED

    def _drain(self) -> None:
        while self._monitor.poll(0):
            try:
                message = recv_monitor_message(self._monitor, zmq.NOBLOCK)
            except zmq.Again:
                return
            event = int(message["event"])
            self._seen[event] = int(message["value"])
            if event & (
                zmq.EVENT_CONNECTED | zmq.EVENT_HANDSHAKE_SUCCEEDED | zmq.EVENT_DISCONNECTED
            ):
                self._link = event

    def explain(self) -> str:
        """Why nothing came: the worst thing the connection saw, in a few words."""
        self._drain()
        seen, where = self._seen, self.endpoint
        hint = (
            " (it was started with --keys DIR: give the same --keys DIR)" if self.local_keys else ""
        )
        if zmq.EVENT_HANDSHAKE_FAILED_AUTH in seen:
            return (
                f"the daemon at {where} refused this client's CURVE key (its public key is not in "
                f"the daemon's allowed_clients/){hint or '; a daemon of another user?'}"
            )
        if seen.get(zmq.EVENT_HANDSHAKE_FAILED_PROTOCOL) == _MECHANISM_MISMATCH:
            if self.with_keys:
                return f"the daemon at {where} does not use CURVE keys (connect without --keys)"
            return (
                f"the daemon at {where} requires CURVE keys: give --keys DIR with its server.key "
                "and your client key (a loopback daemon of another user cannot be used)"
            )
        if (
            zmq.EVENT_HANDSHAKE_FAILED_NO_DETAIL in seen
            or zmq.EVENT_HANDSHAKE_FAILED_PROTOCOL in seen
        ):
            return (
                f"the CURVE handshake with {where} failed: the server.key this client has is not "
                f"that daemon's{hint}"
            )
        if zmq.EVENT_HANDSHAKE_SUCCEEDED in seen and self._link == zmq.EVENT_DISCONNECTED:
            return f"the daemon at {where} closed the connection (it stopped?)"
        if zmq.EVENT_HANDSHAKE_SUCCEEDED in seen:
            return f"connected to {where}, but the daemon did not answer in time (busy or stuck?)"
        if zmq.EVENT_CONNECTED in seen:
            return (
                f"connected to {where}, but the handshake did not finish (is it a sasprobe daemon?)"
            )
        return f"nothing is listening at {where} (is the daemon running?)"

    def close(self) -> None:
        stop_monitor(self._socket, self._monitor)

    def __del__(self) -> None:
        # A client dropped without close(): stop the monitor while its socket is still open.
        monitor = getattr(self, "_monitor", None)  # (None when __init__ failed)
        if monitor is not None and not monitor.closed:
            self.close()
