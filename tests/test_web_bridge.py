"""`sasprobe web`'s server, without a browser: what it serves and to whom, that a page can send
the daemon nothing, that a page which stops reading holds up no other page, and the lines it
refuses to start with. HTTP requests are written with http.client and the WebSocket is read
with the websockets package's own client, both independent of the bridge's code."""

from __future__ import annotations

import base64
import http.client
import json
import os
import threading
import time
from urllib.parse import urlsplit

import numpy as np
import pytest

from tests.conftest import run_cli
from tests.support.daemon_process import DaemonProcess
from tests.support.web import bridge_for, wait_for

TOKEN = "test-token-0123456789abcdef"


@pytest.fixture(scope="module")
def daemon(reference_by_id):
    with DaemonProcess("--molecule", str(reference_by_id["1crn"].path), device="sim:scan") as d:
        yield d


@pytest.fixture(scope="module")
def loopback(daemon):
    with bridge_for(daemon.pub, daemon.ctl) as bridge:
        yield bridge


@pytest.fixture(scope="module")
def exposed(daemon):
    """A bridge on every interface: its token is needed for everything."""
    with bridge_for(daemon.pub, daemon.ctl, "--bind", "0.0.0.0", "--token", TOKEN) as bridge:
        yield bridge


def get(url: str, path: str, headers: dict | None = None) -> tuple[int, bytes, dict]:
    parts = urlsplit(url)
    conn = http.client.HTTPConnection("127.0.0.1", parts.port, timeout=30)
    try:
        conn.putrequest("GET", path, skip_host=True, skip_accept_encoding=True)
        for key, value in {"Host": f"127.0.0.1:{parts.port}", **(headers or {})}.items():
            conn.putheader(key, value)
        conn.endheaders()
        response = conn.getresponse()
        return response.status, response.read(), dict(response.getheaders())
    finally:
        conn.close()


def upgrade(origin: str | None = None) -> dict:
    headers = {
        "Upgrade": "websocket",
        "Connection": "Upgrade",
        "Sec-WebSocket-Key": base64.b64encode(os.urandom(16)).decode(),
        "Sec-WebSocket-Version": "13",
    }
    if origin is not None:
        headers["Origin"] = origin
    return headers


def test_the_page_and_only_its_files_are_served(loopback):
    status, body, headers = get(loopback.url, "/")
    assert status == 200 and b"<canvas>" in body and headers["Content-Type"].startswith("text/html")
    assert "default-src 'none'" in headers["Content-Security-Policy"]
    status, body, headers = get(loopback.url, "/viewer.js")
    assert status == 200 and headers["Content-Type"].startswith("text/javascript")
    for path in (
        "/../pyproject.toml",
        "/%2e%2e/pyproject.toml",
        "/bridge.py",
        "/page/viewer.js",
        "/replay.html",
        "//etc/passwd",
        "/index.html/..",
    ):
        status, body, _ = get(loopback.url, path)
        assert status == 404, (path, status, body)


def test_a_loopback_bridge_answers_only_to_loopback_host_names(loopback):
    port = urlsplit(loopback.url).port
    assert get(loopback.url, "/", {"Host": f"localhost:{port}"})[0] == 200
    for host in (f"attacker.example:{port}", f"192.168.1.5:{port}", "127.0.0.1.example"):
        assert get(loopback.url, "/", {"Host": host})[0] == 403, host
        assert get(loopback.url, "/ws", {"Host": host, **upgrade()})[0] == 403, host


def test_a_websocket_from_a_foreign_origin_is_refused(loopback):
    port = urlsplit(loopback.url).port
    for origin in ("http://attacker.example", f"http://localhost:{port}", "null"):
        assert get(loopback.url, "/ws", upgrade(origin))[0] == 403, origin
    assert get(loopback.url, "/ws", upgrade(f"http://127.0.0.1:{port}"))[0] == 101


def test_beyond_loopback_every_request_needs_the_token(exposed):
    assert urlsplit(exposed.url).path == f"/{TOKEN}/"
    port = urlsplit(exposed.url).port
    own = f"http://127.0.0.1:{port}"
    for path in ("/", "/index.html", "/viewer.js", "/ws", f"/{TOKEN[:-1]}x/", f"/{TOKEN[:-1]}/"):
        assert get(exposed.url, path, upgrade(own) if path.endswith("ws") else None)[0] == 403
    assert get(exposed.url, f"/{TOKEN[:-1]}x/ws", upgrade(own))[0] == 403
    assert get(exposed.url, f"/{TOKEN}/")[0] == 200
    assert get(exposed.url, f"/{TOKEN}/viewer.js")[0] == 200
    assert get(exposed.url, f"/{TOKEN}/ws", upgrade("http://attacker.example"))[0] == 403
    assert get(exposed.url, f"/{TOKEN}/ws", upgrade(own))[0] == 101


def test_beyond_loopback_a_token_is_made_and_printed_in_the_url(daemon):
    with bridge_for(daemon.pub, daemon.ctl, "--bind", "0.0.0.0") as bridge:
        token = urlsplit(bridge.url).path.strip("/")
        assert len(token) >= 16
        assert get(bridge.url, f"/{token}/")[0] == 200
        assert get(bridge.url, "/")[0] == 403


def session(url: str, **options):
    from websockets.sync.client import connect

    parts = urlsplit(url)
    return connect(
        f"ws://127.0.0.1:{parts.port}{parts.path}ws",
        origin=f"http://127.0.0.1:{parts.port}",
        open_timeout=30,
        **options,
    )


def next_pose(ws, timeout_s: float = 30.0) -> dict:
    """Read until a pose arrives (binary packets and other messages are skipped)."""
    deadline = time.monotonic() + timeout_s
    while True:
        message = ws.recv(timeout=max(deadline - time.monotonic(), 0.01))
        if isinstance(message, str) and json.loads(message)["type"] == "pose":
            return json.loads(message)


def test_a_page_is_sent_a_pose_each_time_it_says_it_drew_one(loopback):
    with session(loopback.url) as ws:
        first = next_pose(ws)
        with pytest.raises(TimeoutError):  # no second pose before it drew the first
            next_pose(ws, timeout_s=0.5)
        seqs = [first["seq"]]
        for _ in range(5):
            ws.send(json.dumps({"drawn": seqs[-1]}))
            seqs.append(next_pose(ws)["seq"])
        assert seqs == sorted(seqs) and len(set(seqs)) == len(seqs)


def test_nothing_a_page_sends_reaches_the_daemon(daemon, loopback):
    from sasprobe.protocol.client import ControlClient

    with ControlClient(daemon.ctl, timeout_s=10) as client:
        requests = client.status()["control"]["requests"]
        scene = client.get_scene()
        with session(loopback.url) as ws:
            first = next_pose(ws)
            for junk in (
                {"cmd": "shutdown"},
                {"cmd": "set", "args": {"probe_radius_A": 3.0}},
                {"version": 1, "cmd": "mark", "args": {}},
                {"drawn": "1"},
                "not json",
            ):
                ws.send(junk if isinstance(junk, str) else json.dumps(junk))
            ws.send(b"\x00binary")
            ws.send(json.dumps({"drawn": first["seq"]}))
            next_pose(ws)  # the bridge has read everything sent before
        after = client.status()["control"]["requests"]
        now = client.get_scene()
    assert after == requests + 2  # our own get_scene and status, nothing of the page's
    assert (now["probe_radius_A"], now["marks"]) == (scene["probe_radius_A"], scene["marks"])


def stalled_session(url: str):
    """A page's connection that reads nothing: a small receive buffer, and a client that
    stops reading from the socket once one message waits."""
    import socket

    parts = urlsplit(url)
    sock = socket.socket()
    sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4096)
    sock.connect(("127.0.0.1", parts.port))
    return session(url, sock=sock, max_queue=1, close_timeout=1)


def test_a_page_that_stops_reading_holds_up_no_other_page(daemon, loopback):
    """One page says it drew every pose and never reads; another, drawing as pages do, still
    keeps up with the daemon: after it asks, the poses it gets reach what the daemon
    published before it asked."""
    from sasprobe.protocol.client import Subscriber

    stop = threading.Event()

    def flood(stalled) -> None:
        seq = 0
        while not stop.is_set():
            try:
                stalled.send(json.dumps({"drawn": seq}))
            except Exception:  # noqa: BLE001 - the connection broke: stalled all the same
                return
            seq += 1
            time.sleep(0.0005)

    with stalled_session(loopback.url) as stalled:
        flooding = threading.Thread(target=flood, args=(stalled,), daemon=True)
        flooding.start()
        try:
            with session(loopback.url) as ws, Subscriber(daemon.pub) as sub:
                pose = next_pose(ws)
                for _ in range(10):
                    wait_for(lambda: sub.poll(0.05) is not None and sub.pose, 30, "a daemon pose")
                    published = sub.pose.seq
                    deadline = time.monotonic() + 30
                    while pose["seq"] < published:
                        assert time.monotonic() < deadline, (pose["seq"], published)
                        ws.send(json.dumps({"drawn": pose["seq"]}))
                        pose = next_pose(ws)
        finally:
            stop.set()
            flooding.join(timeout=10)
            stalled.socket.close()


def test_it_refuses_to_start_without_keys_toward_a_remote_daemon():
    r = run_cli(
        "web", "--connect", "tcp://192.0.2.7:5555", "--control", "tcp://192.0.2.7:5556", timeout=60
    )
    assert r.returncode == 2 and r.stdout == ""
    assert r.stderr.count("\n") == 1 and "--keys" in r.stderr, r.stderr


@pytest.mark.parametrize(
    "args, why",
    [
        (("--token", "short"), "--token"),
        (("--port", "70000"), "port"),
        (("--connect", "udp://x"), "endpoint"),
    ],
)
def test_bad_options_are_one_line(args, why):
    r = run_cli("web", *args, timeout=60)
    assert r.returncode == 2 and r.stderr.count("\n") == 1 and why in r.stderr, r.stderr


def messages(ws, timeout_s: float = 30.0):
    """Every message as it comes: (kind, content), binary packets read with web/packets.py's
    layout; `drawn` acknowledged for each pose so poses keep coming."""
    from sasprobe.web.packets import read_packet

    deadline = time.monotonic() + timeout_s
    while True:
        message = ws.recv(timeout=max(deadline - time.monotonic(), 0.01))
        if isinstance(message, bytes):
            header, arrays = read_packet(message)
            yield header["kind"], (header, arrays)
            continue
        value = json.loads(message)
        if value["type"] == "pose":
            ws.send(json.dumps({"drawn": value["seq"]}))
        yield value["type"], value


def wait_message(ws, what, why: str, timeout_s: float = 60.0):
    """The first message for which what(kind, content) holds."""
    for kind, content in messages(ws, timeout_s):
        if what(kind, content):
            return content
    raise AssertionError(why)


def test_it_follows_a_daemon_started_after_it_its_loads_and_its_marks(reference_by_id, tmp_path):
    from sasprobe.molecule import load_structure
    from sasprobe.protocol.client import ControlClient

    pub, ctl = f"ipc://{tmp_path}/pub", f"ipc://{tmp_path}/ctl"
    crambin = load_structure(reference_by_id["1crn"].path)
    other = reference_by_id["1oky"].path
    with (
        bridge_for(pub, ctl) as bridge,
        session(bridge.url) as ws,
    ):
        gone = wait_message(ws, lambda k, c: k == "daemon", "the daemon's absence")
        assert gone["connected"] is False
        with DaemonProcess(
            "--molecule", str(reference_by_id["1crn"].path), device="sim:scan", pub=pub, ctl=ctl
        ) as daemon:
            header, arrays = wait_message(ws, lambda k, c: k == "structure", "a structure")
            assert header["sha256"] == crambin.sha256 and header["n_atoms"] == crambin.n_atoms
            np.testing.assert_allclose(
                arrays["positions"].reshape(-1, 3), crambin.positions, atol=1e-4
            )
            wait_message(ws, lambda k, c: k == "pose", "a pose")
            with ControlClient(daemon.ctl, timeout_s=60) as client:
                mark = client.mark("pocket")["mark"]
                wait_message(
                    ws,
                    lambda k, c: k == "scene" and mark in c["scene"]["marks"],
                    "the mark in a scene",
                )
                loaded = client.load(path=other)["structure"]
            header, _ = wait_message(ws, lambda k, c: k == "structure", "the loaded structure")
            assert header["sha256"] == loaded["sha256"] and header["name"] == "1oky"
            wait_message(
                ws,
                lambda k, c: k == "colors" and c[0]["sha256"] == loaded["sha256"],
                "its colours",
            )


def test_a_daemon_publishing_every_fourth_pose_is_followed_at_its_loop_rate(reference_by_id):
    """At 4 kHz the daemon publishes every 4th tick's pose (the scene's `pose_every`): a page
    is sent those poses, and the rate it shows is the loop's ticks over device time, not the
    poses it was sent."""
    crambin = str(reference_by_id["1crn"].path)
    with (
        DaemonProcess("--molecule", crambin, "--rate", "4000", device="sim:scan") as fast,
        bridge_for(fast.pub, fast.ctl) as bridge,
        session(bridge.url) as ws,
    ):
        scene = wait_message(ws, lambda kind, _: kind == "scene", "a scene")["scene"]
        assert scene["pose_every"] == 4
        seqs, rate = [], None
        for kind, content in messages(ws, 120):
            if kind == "pose":
                seqs.append(content["seq"])
                rate = content["stats"].get("rate_hz") or rate
                if len(seqs) >= 5 and rate is not None:
                    break
        assert all(seq % 4 == 0 for seq in seqs), seqs
        assert seqs == sorted(seqs) and len(set(seqs)) == len(seqs)
        # poses are published at 1 kHz; the rate shown counts the loop's ticks, 4 kHz less
        # what a loaded machine makes the loop skip
        assert 2000 < rate <= 4400, rate


def test_a_follow_thread_still_running_at_stop_keeps_its_sockets(monkeypatch):
    """A bridge stopping on a loaded machine: the follow thread has not ended within the wait,
    so its sockets are not closed under it (ZeroMQ would raise in that thread, a traceback on
    the way out); they are closed once the thread has ended."""
    from sasprobe.web import feed as feed_module

    release, closed_while_running = threading.Event(), []

    class StarvedFollow:  # a poll that does not come back until released
        subscriber = type("S", (), {"scene": None})()
        connected = False

        def poll(self, timeout_s: float = 0.0):
            release.wait(20)
            return []

        def take_new_structure(self):
            return None

        def close(self):
            closed_while_running.append(feed._thread.is_alive())

    monkeypatch.setattr(feed_module, "STOP_S", 0.2)
    feed = feed_module.Feed(StarvedFollow())
    feed.start()
    time.sleep(0.1)
    feed.stop()
    assert closed_while_running == []  # the thread still polls: not closed under it
    release.set()
    feed._thread.join(10)
    assert not feed._thread.is_alive()
    feed.stop()
    assert closed_while_running == [False]
