"""Endpoints, the loopback rule, and CURVE with an allow-list over real sockets."""

from __future__ import annotations

import os
import stat
import time

import pytest
import zmq
from sasprobe.daemon.config import check_bind_security
from sasprobe.daemon.publisher import Publisher
from sasprobe.protocol.client import Subscriber
from sasprobe.protocol.endpoints import EndpointError, parse_endpoint
from sasprobe.protocol.security import (
    generate_keys,
    load_client_keys,
    load_server_keys,
    start_authenticator,
)
from zmq.utils.monitor import recv_monitor_message

from sasprobe.common.errors import UserError
from tests.support.daemon_process import free_port


@pytest.mark.parametrize(
    "text, loopback",
    [
        ("tcp://127.0.0.1:5555", True),
        ("tcp://127.3.2.1:1", True),
        ("tcp://localhost:5555", True),
        ("tcp://[::1]:5555", True),
        ("ipc:///tmp/sasprobe-pub", True),
        ("tcp://0.0.0.0:5555", False),
        ("tcp://*:5555", False),
        ("tcp://192.168.1.20:5555", False),
        ("tcp://eth0:5555", False),
        ("tcp://myhost.example:5555", False),
    ],
)
def test_loopback_detection(text, loopback):
    assert parse_endpoint(text).is_loopback is loopback


@pytest.mark.parametrize(
    "text",
    ["127.0.0.1:5555", "udp://1.2.3.4:5", "tcp://host", "tcp://h:0", "tcp://h:99999", "ipc://"],
)
def test_bad_endpoints_are_refused(text):
    with pytest.raises(EndpointError):
        parse_endpoint(text)


def test_non_loopback_bind_needs_keys(tmp_path):
    check_bind_security(["tcp://127.0.0.1:5555", "ipc:///tmp/x"], None)
    with pytest.raises(UserError, match="refusing to bind tcp://0.0.0.0:5555 without encryption"):
        check_bind_security(["tcp://127.0.0.1:5556", "tcp://0.0.0.0:5555"], None)
    check_bind_security(["tcp://0.0.0.0:5555"], str(tmp_path))


def test_key_files_and_errors(tmp_path):
    created = generate_keys(tmp_path, ("alice", "bob"))
    names = sorted(p.name for p in created)
    assert "server.key_secret" in names and "alice.key" in names and "bob.key_secret" in names
    assert (tmp_path / "server.key_secret").stat().st_mode & 0o077 == 0
    assert (tmp_path / "allowed_clients" / "bob.key").is_file()
    server = load_server_keys(tmp_path)
    alice = load_client_keys(tmp_path, "alice")
    assert alice.server_public == server.public and alice.public != server.public
    with pytest.raises(UserError, match="already exists"):
        generate_keys(tmp_path, ("alice",))
    with pytest.raises(UserError, match="no such key file"):
        load_client_keys(tmp_path, "carol")


def test_curve_allowed_client_receives_and_unknown_key_is_rejected(tmp_path):
    """Over TCP, and over the ipc:// endpoint the same socket binds: CURVE is the socket's,
    so a client without keys gets nothing there either. The socket file is 0600 and goes
    with the socket."""
    allowed_dir = tmp_path / "daemon-keys"
    generate_keys(allowed_dir, ("client",))
    stranger_dir = tmp_path / "stranger"
    generate_keys(stranger_dir, ("client",))
    (stranger_dir / "server.key").write_bytes(
        (allowed_dir / "server.key").read_bytes()
    )  # knows the server key

    context = zmq.Context()
    auth = start_authenticator(context, load_server_keys(allowed_dir))
    port = free_port()
    ipc = tmp_path / "pub"
    pub = Publisher(
        context, [f"tcp://0.0.0.0:{port}", f"ipc://{ipc}"], load_server_keys(allowed_dir)
    )
    assert stat.S_IMODE(os.stat(ipc).st_mode) == 0o600
    friend = Subscriber(
        f"tcp://127.0.0.1:{port}", keys=load_client_keys(allowed_dir), context=context
    )
    friend_ipc = Subscriber(f"ipc://{ipc}", keys=load_client_keys(allowed_dir), context=context)
    plain_ipc = Subscriber(f"ipc://{ipc}", context=context)  # ipc:// alone would need no keys
    stranger_keys = load_client_keys(stranger_dir)
    stranger_sock = context.socket(zmq.SUB)
    stranger_sock.linger = 0
    stranger_sock.curve_secretkey, stranger_sock.curve_publickey = (
        stranger_keys.secret,
        stranger_keys.public,
    )
    stranger_sock.curve_serverkey = stranger_keys.server_public
    monitor = stranger_sock.get_monitor_socket()
    stranger_sock.setsockopt(zmq.SUBSCRIBE, b"")
    stranger_sock.connect(f"tcp://127.0.0.1:{port}")
    plain = Subscriber(f"tcp://127.0.0.1:{port}", context=context)  # no CURVE at all
    try:
        from sasprobe.protocol.pose import Pose, encode_pose

        deadline = time.monotonic() + 10
        received = []
        seq = 0
        while time.monotonic() < deadline and (
            len(received) < 20 or friend_ipc.poses_received < 20
        ):
            pub.poll_subscriptions()
            pub.publish_pose(encode_pose(Pose(seq=seq)))
            seq += 1
            received += friend.poll(0.01)
            friend_ipc.poll()
            plain.poll()
            plain_ipc.poll()
        assert len(received) >= 20 and friend_ipc.poses_received >= 20, (
            "the allowed client got no poses"
        )
        events = []
        deadline = time.monotonic() + 5
        while time.monotonic() < deadline and zmq.EVENT_HANDSHAKE_FAILED_AUTH not in events:
            if monitor.poll(100):
                events.append(recv_monitor_message(monitor)["event"])
        assert zmq.EVENT_HANDSHAKE_FAILED_AUTH in events, (
            f"unknown key was not refused: events {events}"
        )
        assert stranger_sock.poll(0) == 0, "the unknown key received data"
        assert plain.poses_received == 0 and plain_ipc.poses_received == 0
    finally:
        friend.close()
        friend_ipc.close()
        plain.close()
        plain_ipc.close()
        stranger_sock.disable_monitor()
        monitor.close(linger=0)
        stranger_sock.close()
        pub.close()
        auth.stop()
        context.term()
    assert not ipc.exists(), "the socket file outlived its socket"
