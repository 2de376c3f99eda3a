"""The PUB side: poses every tick and the scene, never blocking the loop, never doing a
client's work on it.

An XPUB socket (a PUB that also sees subscriptions) lets the daemon send the scene the
moment someone subscribes. Sends are non-blocking: a subscriber that no longer reads fills
its own queue (SNDHWM messages) and then loses poses; the daemon never waits for it.

libzmq applies subscriptions (a trie of topics) on the thread that uses the socket, the
loop's, so what a client can make it do there is bounded: a subscription is at most
MAX_SUBSCRIPTION_BYTES (a longer message drops that connection before it is read),
at most SUBSCRIPTION_HWM wait per connection, and once MAX_FOREIGN_SUBSCRIPTIONS
subscriptions to topics the daemon never publishes have come in, the socket is made
anew (everyone reconnects within a fraction of a second; the trie's memory is freed).
Subscribers are counted from connection events (daemon/socket_monitor.py), not from
subscription frames, which a raw client could forge both ways.
"""

from __future__ import annotations

import logging
import time

import zmq
from sasprobe.daemon.socket_monitor import SocketMonitor
from sasprobe.protocol.endpoints import remove_socket_files, socket_files
from sasprobe.protocol.pose import POSE_TOPIC
from sasprobe.protocol.scene import SCENE_TOPIC
from sasprobe.protocol.security import ServerKeys, bind_server_socket

from sasprobe.common.errors import UserError

log = logging.getLogger("sasprobe")

SNDHWM = 2000  # messages queued per subscriber (2 s of poses at 1 kHz) before it drops
# a ZMTP frame: a subscription (ours are 5-6 bytes), or a CURVE handshake command (<= ~300)
MAX_SUBSCRIPTION_BYTES = 1024
SUBSCRIPTION_HWM = 16  # subscription messages queued per connection
# subscriptions to topics never published, before the socket is renewed
MAX_FOREIGN_SUBSCRIPTIONS = 1024
SCENE_ON_JOIN_NS = 100_000_000  # a joining subscriber's scene goes out at most this often
REBIND_RETRY_NS = 50_000_000


class Publisher:
    def __init__(
        self,
        context: zmq.Context,
        endpoints: list[str],
        keys: ServerKeys | None = None,
        sndhwm: int = SNDHWM,
    ) -> None:
        self._context = context
        self._keys = keys
        self._sndhwm = sndhwm
        self.poses_sent = 0
        self.scenes_sent = 0
        self.send_failures = 0  # sends the socket refused (never blocks; counted, not hidden)
        self.renewals = 0  # times the socket was made anew (subscription flood)
        self._foreign = 0
        self._last_join_ns = -SCENE_ON_JOIN_NS
        self._join_pending = False
        self._retry_at_ns: int | None = None
        self._socket, self.endpoints = self._make(endpoints)

    def _make(self, endpoints: list[str]) -> tuple[zmq.Socket, list[str]]:
        sock = self._context.socket(zmq.XPUB)
        sock.linger = 0
        sock.sndhwm = self._sndhwm
        sock.rcvhwm = SUBSCRIPTION_HWM
        sock.setsockopt(zmq.MAXMSGSIZE, MAX_SUBSCRIPTION_BYTES)
        sock.setsockopt(zmq.XPUB_VERBOSER, 1)  # every (un)subscription reaches us
        self._monitor = SocketMonitor(sock, "publisher", self._keys is not None)
        try:
            bound = bind_server_socket(sock, endpoints, self._keys)
        except BaseException:
            self._monitor.close()
            raise
        self._files = socket_files(bound)
        return sock, bound

    @property
    def subscribers(self) -> int:
        """Connections open to the publisher (each a subscriber, or a client being refused)."""
        return self._monitor.peers

    def _send(self, topic: bytes, payload: bytes) -> bool:
        if self._socket is None:
            self.send_failures += 1
            return False
        try:
            self._socket.send_multipart((topic, payload), zmq.NOBLOCK, copy=True)
            return True
        except zmq.Again:
            self.send_failures += 1
            return False

    def publish_pose(self, payload: bytes) -> None:
        if self._send(POSE_TOPIC, payload):
            self.poses_sent += 1

    def publish_scene(self, payload: bytes) -> None:
        if self._send(SCENE_TOPIC, payload):
            self.scenes_sent += 1

    def poll_subscriptions(self, now_ns: int | None = None) -> bool:
        """Read pending (un)subscriptions and connection events without blocking; True when a
        subscriber joined and is due its scene."""
        now_ns = time.monotonic_ns() if now_ns is None else now_ns
        if self._socket is None:
            self._renew(now_ns)
            return False
        self._monitor.drain()
        for _ in range(SUBSCRIPTION_HWM):
            if not self._socket.getsockopt(zmq.EVENTS) & zmq.POLLIN:
                break
            try:
                message = self._socket.recv(zmq.NOBLOCK)
            except zmq.Again:
                break
            if not message or message[0] not in (0, 1):
                continue
            topic = message[1:]
            if POSE_TOPIC.startswith(topic) or SCENE_TOPIC.startswith(topic):
                self._join_pending |= message[0] == 1 and SCENE_TOPIC.startswith(topic)
            elif message[0] == 1:
                self._foreign += 1
        if self._foreign > MAX_FOREIGN_SUBSCRIPTIONS:
            log.warning(
                "publisher: %d subscriptions to topics the daemon does not publish; the socket "
                "is made anew (subscribers reconnect by themselves)",
                self._foreign,
            )
            self._close_socket()
            self.renewals += 1
            self._retry_at_ns = now_ns
            return False
        if self._join_pending and now_ns - self._last_join_ns >= SCENE_ON_JOIN_NS:
            self._join_pending = False
            self._last_join_ns = now_ns
            return True
        return False

    def _renew(self, now_ns: int) -> None:
        if now_ns < self._retry_at_ns:
            return
        try:
            self._socket, self.endpoints = self._make(self.endpoints)
            self._foreign = 0
        except (zmq.ZMQError, UserError):  # the old listener is not gone yet
            self._retry_at_ns = now_ns + REBIND_RETRY_NS

    def _close_socket(self) -> None:
        if self._socket is not None:
            self._monitor.close()
            self._socket.close(linger=0)
            self._socket = None
            remove_socket_files(self._files)

    def close(self) -> None:
        self._close_socket()
