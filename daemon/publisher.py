"""The PUB side: poses every tick and the scene, never blocking the loop.

An XPUB socket (a PUB that also sees subscriptions) lets the daemon count subscribers
and send the scene the moment one joins. Sends are non-blocking: a subscriber that
stops reading fills its own queue (SNDHWM messages) and then loses poses; the daemon
never waits for it.
"""

from __future__ import annotations

import zmq

from sasprobe.protocol.pose import POSE_TOPIC
from sasprobe.protocol.scene import SCENE_TOPIC
from sasprobe.protocol.security import ServerKeys, bind_server_socket

SNDHWM = 2000  # messages queued per subscriber (2 s of poses at 1 kHz) before it drops


class Publisher:
    def __init__(self, context: zmq.Context, endpoints: list[str], keys: ServerKeys | None = None,
                 sndhwm: int = SNDHWM) -> None:
        self._socket = context.socket(zmq.XPUB)
        self._socket.linger = 0
        self._socket.sndhwm = sndhwm
        self._socket.setsockopt(zmq.XPUB_VERBOSER, 1)  # every (un)subscription, so they can be counted
        self.endpoints = bind_server_socket(self._socket, endpoints, keys)
        self.poses_sent = 0
        self.scenes_sent = 0
        self.send_failures = 0  # sends the socket refused (never blocks; counted, not hidden)
        self.subscribers = 0  # pose subscriptions currently active

    def _send(self, topic: bytes, payload: bytes) -> bool:
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

    def poll_subscriptions(self) -> bool:
        """Read pending (un)subscriptions without blocking; True when someone new subscribed."""
        joined = False
        while self._socket.getsockopt(zmq.EVENTS) & zmq.POLLIN:
            try:
                message = self._socket.recv(zmq.NOBLOCK)
            except zmq.Again:
                break
            if not message:
                continue
            topic = message[1:]
            if not POSE_TOPIC.startswith(topic):  # a prefix of b"pose" (b"" too) receives poses
                if message[0] == 1 and SCENE_TOPIC.startswith(topic):
                    joined = True
                continue
            if message[0] == 1:
                self.subscribers += 1
                joined = True
            elif message[0] == 0:
                self.subscribers = max(self.subscribers - 1, 0)
        return joined

    def close(self) -> None:
        self._socket.close(linger=0)
