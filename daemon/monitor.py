"""What happens on a server socket's connections: peers, refused handshakes, running out of fds.

Each server socket (publisher, control) has a ZeroMQ socket monitor, drained without
blocking by the thread that owns the socket, a bounded number of events per call:

- peers are counted from accepted and closed connections (by file descriptor), so no
  message a client sends can forge the count (a connection that fails its handshake
  counts until it is dropped, within HANDSHAKE_IVL_MS);
- failed handshakes are logged, at most one line per kind every LOG_INTERVAL_S, saying
  what the client got wrong (refused keys are logged by the allow-list itself);
- when accept() fails for lack of file descriptors, libzmq's I/O thread would retry it
  in a tight loop; the owner then unbinds for PAUSE_S (existing connections stay) and
  binds again. Raising the soft fd limit and dropping connections that do not finish
  their handshake within HANDSHAKE_IVL_MS (clients without keys never do) make that rare.
"""

from __future__ import annotations

import errno
import logging
import os
import time

import zmq
from zmq.utils.monitor import recv_monitor_message

from sasprobe.protocol.endpoints import private_umask

log = logging.getLogger("sasprobe")

EVENTS = (zmq.EVENT_ACCEPTED | zmq.EVENT_DISCONNECTED | zmq.EVENT_ACCEPT_FAILED
          | zmq.EVENT_HANDSHAKE_FAILED_NO_DETAIL | zmq.EVENT_HANDSHAKE_FAILED_PROTOCOL)
HANDSHAKE_IVL_MS = 2000  # a connection that has not finished its handshake by then is dropped
MAX_EVENTS_PER_DRAIN = 16  # bounded work for the loop thread even while events flood in
LOG_INTERVAL_S = 10.0
PAUSE_S = 1.0  # no accepting for this long once accept() ran out of file descriptors
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
        self._monitor = socket.get_monitor_socket(EVENTS)
        self._peers: set[int] = set()
        self.failed_handshakes = 0
        self.accept_failures = 0
        self._last_log: dict[str, float] = {}
        self.out_of_fds = False  # set when accept() failed for lack of descriptors (the owner pauses)

    @property
    def peers(self) -> int:
        return len(self._peers)

    def drain(self) -> None:
        for _ in range(MAX_EVENTS_PER_DRAIN):
            if not self._monitor.getsockopt(zmq.EVENTS) & zmq.POLLIN:
                return
            try:
                message = recv_monitor_message(self._monitor, zmq.NOBLOCK)
            except zmq.Again:
                return
            self._event(int(message["event"]), int(message["value"]))

    def _event(self, event: int, value: int) -> None:
        if event == zmq.EVENT_ACCEPTED:  # the value is the connection's fd (not so for a handshake)
            self._peers.add(value)
        elif event == zmq.EVENT_DISCONNECTED:
            self._peers.discard(value)
        elif event == zmq.EVENT_ACCEPT_FAILED:
            self.accept_failures += 1
            if value in _OUT_OF_FDS:
                self.out_of_fds = True
                self._say("fds", f"the {self.label} cannot accept connections: {os.strerror(value)}; not "
                                 f"accepting for {PAUSE_S:g} s (existing clients stay connected)")
        else:
            self.failed_handshakes += 1
            if event == zmq.EVENT_HANDSHAKE_FAILED_PROTOCOL and value == _MECHANISM_MISMATCH:
                why = ("without CURVE keys (this daemon requires them)" if self.curve
                       else "with CURVE keys (this socket uses none)")
                self._say("mechanism", f"a client of the {self.label} connected {why}; it was refused")
            else:
                self._say("handshake", f"a client of the {self.label} failed the CURVE handshake: it does not "
                                       f"have this daemon's server key")

    def _say(self, kind: str, line: str) -> None:
        now = time.monotonic()
        if now - self._last_log.get(kind, -LOG_INTERVAL_S) >= LOG_INTERVAL_S:
            self._last_log[kind] = now
            log.warning("%s", line)

    def close(self) -> None:
        self._monitor.close(linger=0)


class AcceptPause:
    """The owner's side of running out of descriptors: unbind, wait PAUSE_S, bind again."""

    def __init__(self, socket: zmq.Socket, bound: list[str]) -> None:
        self._socket = socket
        self._bound = bound  # the addresses as bound (LAST_ENDPOINT), which unbind() needs
        self._unbound: list[str] = []
        self._resume_at = 0.0

    def service(self, monitor: SocketMonitor) -> None:
        if monitor.out_of_fds and not self._unbound:
            monitor.out_of_fds = False
            for endpoint in self._bound:
                try:
                    self._socket.unbind(endpoint)
                except zmq.ZMQError:
                    pass
            self._unbound = list(self._bound)
            self._resume_at = time.monotonic() + PAUSE_S
        elif self._unbound and time.monotonic() >= self._resume_at:
            while self._unbound:
                try:
                    with private_umask():  # an ipc:// socket file 0600 again
                        self._socket.bind(self._unbound[0])
                except zmq.ZMQError:  # the old listener not gone yet, or still no descriptors: later
                    self._resume_at = time.monotonic() + PAUSE_S / 10
                    return
                self._unbound.pop(0)
            monitor.out_of_fds = False
