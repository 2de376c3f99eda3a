"""What happens on a server socket's connections: peers, refused handshakes, running out of fds.

Each server socket (publisher, control) has a ZeroMQ socket monitor, drained without
blocking by the thread that owns the socket, a bounded number of events per call:

- peers are counted from accepted and closed connections (by file descriptor), so no
  message a client sends can forge the count (a connection that fails its handshake
  counts until it is dropped, within HANDSHAKE_IVL_MS);
- failed handshakes are logged, at most one line per kind every LOG_INTERVAL_S, saying
  what the client got wrong (refused keys are logged by the allow-list itself);
- accept() failing for lack of file descriptors is logged. Raising the soft fd limit to
  the hard one and dropping connections that do not finish their handshake within
  HANDSHAKE_IVL_MS (clients without the keys never do) keep it rare. (Unbinding until
  descriptors are free again was tried and dropped: libzmq aborts the process when a
  bind meets EMFILE.)
"""

from __future__ import annotations

import errno
import logging
import os
import struct
import time

import zmq
from sasprobe.protocol.handshake import start_monitor, stop_monitor

log = logging.getLogger("sasprobe")

EVENTS = (
    zmq.EVENT_ACCEPTED
    | zmq.EVENT_DISCONNECTED
    | zmq.EVENT_ACCEPT_FAILED
    | zmq.EVENT_HANDSHAKE_FAILED_NO_DETAIL
    | zmq.EVENT_HANDSHAKE_FAILED_PROTOCOL
)
HANDSHAKE_IVL_MS = 2000  # a connection that has not finished its handshake by then is dropped
MAX_EVENTS_PER_DRAIN = 16  # bounded work for the loop thread even while events flood in
LOG_INTERVAL_S = 10.0
# A monitor event's first frame: the event (uint16) and its value (uint32), native order
# (libzmq's zmq_socket_monitor). Read as plain integers: pyzmq's recv_monitor_message makes
# each value an Event flag, and the enum caches every new combination, one more for each
# descriptor number a refused connection had.
_EVENT = struct.Struct("=HI")
_MECHANISM_MISMATCH = 0x11000002  # ZMQ_PROTOCOL_ERROR_ZMTP_MECHANISM_MISMATCH
_OUT_OF_FDS = (errno.EMFILE, errno.ENFILE)


def raise_fd_limit() -> None:
    """The soft limit on open files up to the hard one (once, at start-up)."""
    import resource

    soft, hard = resource.getrlimit(resource.RLIMIT_NOFILE)
    if soft < hard:
        try:
            resource.setrlimit(resource.RLIMIT_NOFILE, (hard, hard))
        except (ValueError, OSError):
            pass


class SocketMonitor:
    def __init__(self, socket: zmq.Socket, label: str, curve: bool) -> None:
        self.label = label
        self.curve = curve
        socket.setsockopt(zmq.HANDSHAKE_IVL, HANDSHAKE_IVL_MS)
        self._socket = socket
        self._monitor = start_monitor(socket, EVENTS)
        self._peers: set[int] = set()
        self.failed_handshakes = 0
        self.accept_failures = 0
        self._last_log: dict[str, float] = {}

    @property
    def peers(self) -> int:
        return len(self._peers)

    def drain(self) -> None:
        for _ in range(MAX_EVENTS_PER_DRAIN):
            if not self._monitor.getsockopt(zmq.EVENTS) & zmq.POLLIN:
                return
            try:
                frames = self._monitor.recv_multipart(zmq.NOBLOCK)
            except zmq.Again:
                return
            if len(frames[0]) == _EVENT.size:
                self._event(*_EVENT.unpack(frames[0]))

    def _event(self, event: int, value: int) -> None:
        if event == zmq.EVENT_ACCEPTED:  # the value is the connection's fd (not so for a handshake)
            self._peers.add(value)
        elif event == zmq.EVENT_DISCONNECTED:
            self._peers.discard(value)
        elif event == zmq.EVENT_ACCEPT_FAILED:
            self.accept_failures += 1
            if value in _OUT_OF_FDS:
                self._say(
                    "fds",
                    f"the {self.label} cannot accept connections: {os.strerror(value)} (a client "
                    f"holding many connections?)",
                )
        else:
            self.failed_handshakes += 1
            if event == zmq.EVENT_HANDSHAKE_FAILED_PROTOCOL and value == _MECHANISM_MISMATCH:
                why = (
                    "without CURVE keys (this daemon requires them)"
                    if self.curve
                    else "with CURVE keys (this socket uses none)"
                )
                self._say(
                    "mechanism", f"a client of the {self.label} connected {why}; it was refused"
                )
            else:
                self._say(
                    "handshake",
                    f"a client of the {self.label} failed the CURVE handshake: it does not "
                    f"have this daemon's server key",
                )

    def _say(self, kind: str, line: str) -> None:
        now = time.monotonic()
        if now - self._last_log.get(kind, -LOG_INTERVAL_S) >= LOG_INTERVAL_S:
            self._last_log[kind] = now
            log.warning("%s", line)

    def close(self) -> None:
        """Before the socket closes (protocol/handshake.py `stop_monitor`)."""
        stop_monitor(self._socket, self._monitor)
