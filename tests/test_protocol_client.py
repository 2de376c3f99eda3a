"""The subscriber client over a real PUB socket: latest pose and scene, drops counted."""

from __future__ import annotations

import errno
import threading
import time

import numpy as np
import pytest
import zmq
from sasprobe.protocol.client import ControlClient, Subscriber
from sasprobe.protocol.pose import POSE_TOPIC, Pose, encode_pose
from sasprobe.protocol.scene import (
    SCENE_TOPIC,
    SceneError,
    decode_scene,
    encode_scene,
    validate_scene,
)

from tests.support.scene import example_scene


@pytest.fixture()
def pub_and_sub(tmp_path):
    context = zmq.Context()
    pub = context.socket(zmq.PUB)
    pub.linger = 0
    endpoint = f"ipc://{tmp_path}/pub"
    pub.bind(endpoint)
    sub = Subscriber(endpoint, context=context)
    # PUB/SUB joins asynchronously: publish until the subscriber sees something.
    deadline = time.monotonic() + 5
    while sub.poses_received == 0 and time.monotonic() < deadline:
        pub.send_multipart([POSE_TOPIC, encode_pose(Pose(seq=0))])
        sub.poll(0.01)
    assert sub.poses_received > 0
    yield pub, sub
    sub.close()
    pub.close()
    context.term()


def test_poll_drains_everything_and_keeps_the_newest(pub_and_sub):
    pub, sub = pub_and_sub
    start = sub.pose.seq + 1
    for seq in range(start, start + 500):
        pub.send_multipart(
            [POSE_TOPIC, encode_pose(Pose(seq=seq, force_N=np.array([seq, 0.0, 0.0])))]
        )
    pub.send_multipart([SCENE_TOPIC, encode_scene(example_scene())])
    got = []
    deadline = time.monotonic() + 5
    while sub.scene is None and time.monotonic() < deadline:
        got += sub.poll(0.05)
    assert [p.seq for p in got] == list(range(start, start + 500))
    assert sub.pose.seq == start + 499 and sub.pose.force_N[0] == start + 499
    assert sub.scene["structure"]["name"] == "1crn"
    t0 = time.monotonic()
    assert sub.poll() == [] and time.monotonic() - t0 < 0.5  # nothing queued: returns at once


def test_malformed_messages_are_dropped_and_counted(pub_and_sub):
    pub, sub = pub_and_sub
    pub.send_multipart([POSE_TOPIC, b"short"])
    pub.send_multipart([SCENE_TOPIC, b"{not json"])
    pub.send_multipart([SCENE_TOPIC, b'{"version": 1}'])
    pub.send_multipart([POSE_TOPIC, encode_pose(Pose()), b"extra frame"])
    deadline = time.monotonic() + 5
    while sub.malformed < 4 and time.monotonic() < deadline:
        sub.poll(0.05)
    assert sub.malformed == 4 and sub.scene is None and sub.missed == 0


def _poses_after_a_scene(pub, sub, scene, seqs) -> None:
    pub.send_multipart([SCENE_TOPIC, encode_scene(scene)])
    for seq in seqs:
        pub.send_multipart([POSE_TOPIC, encode_pose(Pose(seq=seq))])
    deadline = time.monotonic() + 5
    while sub.pose.seq != seqs[-1] and time.monotonic() < deadline:
        sub.poll(0.05)
    assert sub.pose.seq == seqs[-1]


def test_lost_poses_are_counted_in_steps_of_the_scenes_pose_every(pub_and_sub):
    """Before a scene says how far apart poses are, a gap says nothing; with `pose_every` 4
    (a 4 kHz daemon publishes every 4th tick), only a gap beyond 4 ticks lost poses."""
    pub, sub = pub_and_sub
    seq = sub.pose.seq
    _poses_after_a_scene(pub, sub, example_scene(), [seq + 10])
    assert sub.missed == 9  # 1 a pose: 9 lost in between
    base = seq + 12
    _poses_after_a_scene(
        pub, sub, {**example_scene(), "pose_every": 4}, [base, base + 4, base + 16]
    )
    assert sub.missed == 9 + 2


def test_scene_decoder_rejects_bad_scenes():
    for broken in (
        {"version": 0},
        {**example_scene(), "clip_planes": [[0, 0, 0, 1]]},
        {
            **example_scene(),
            "haptics": {"method": "magic", "stiffness_n_per_mm": 1, "damping_n_s_per_m": 0},
        },
    ):
        with pytest.raises(SceneError):
            validate_scene(broken)
    with pytest.raises(SceneError):
        decode_scene(b'{"version": NaN}')


def test_a_publisher_faster_than_the_caller_does_not_keep_poll(pub_and_sub):
    """Poses arriving as fast as they are taken: poll returns after a queue's worth, the
    newest taken (a demo on a starved machine was kept in poll for minutes)."""
    _, sub = pub_and_sub
    sub.close()

    class Endless:
        """A socket whose queue never empties: each pose taken, the next has arrived."""

        rcvhwm = 100
        seq = 1000

        def recv_multipart(self, flags=0):
            self.seq += 1
            return [POSE_TOPIC, encode_pose(Pose(seq=self.seq))]

        def close(self, linger=None):
            pass

    sub._socket = Endless()
    outcome = {}
    caller = threading.Thread(target=lambda: outcome.setdefault("poses", sub.poll()), daemon=True)
    caller.start()
    caller.join(timeout=30)
    assert not caller.is_alive(), "poll() never returned"
    assert [p.seq for p in outcome["poses"]] == list(range(1001, 1101))


def test_clients_dropped_without_close_leave_their_context_whole(tmp_path):
    """A client stops its connection monitor before its socket closes, even when it is dropped
    without close(): libzmq keeps a socket closed with its monitor running, and the monitor,
    for good, and pyzmq names a monitor after its socket's descriptor, which a new socket may
    reuse. Dropped clients then used up the context, or a new client could not start its
    monitor: ControlClient failed before its request went out."""
    context = zmq.Context()
    context.set(zmq.MAX_SOCKETS, 64)  # the sockets of about 20 clients
    endpoint = f"ipc://{tmp_path}/nobody"

    def opened(make):
        """make() once the context has room: libzmq's reaper thread frees a closed socket's
        place (later, on a busy machine); a socket kept for good never frees it."""
        deadline = time.monotonic() + 10
        while True:
            try:
                return make()
            except zmq.ZMQError as exc:
                if exc.errno != errno.EMFILE or time.monotonic() > deadline:
                    raise
                time.sleep(0.01)

    for _ in range(100):
        opened(lambda: Subscriber(endpoint, context=context))  # dropped at once
        opened(lambda: ControlClient(endpoint, context=context)._open())
    context.term()  # (after a failure above it would wait for the kept sockets forever)
