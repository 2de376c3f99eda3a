"""The daemon as a real process shared by the module: poses over real sockets, control,
recording, status, security, user errors (test_daemon_sessions.py: one daemon per test).

The timing bar is ≥ 95 % of poses and nothing tighter, because the machine
running the tests is shared.
"""

from __future__ import annotations

import json
import threading
import time

import numpy as np
import pytest
import zmq
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from sasprobe.molecule import parse_structure
from sasprobe.molecule.packed import unpack_structure
from sasprobe.protocol.client import ControlClient, ControlError, Subscriber, fetch_structure
from sasprobe.protocol.control import decode_reply
from sasprobe.protocol.recording import iter_items
from sasprobe.protocol.scene import SCENE_VERSION

from tests.conftest import run_cli
from tests.support.bounded import join
from tests.support.daemon_process import DaemonProcess, cli_many, collect_raw, free_port
from tests.support.schema_check import check_pose_payload, check_raw_reply


@pytest.fixture(scope="module")
def daemon():
    with DaemonProcess("--record-dir", ".") as d:  # its private working folder
        yield d
        rc, report = d.stop()
        assert rc == 0, d.stderr


def _coverage(payloads: list[bytes]) -> tuple[float, list[dict]]:
    decoded = [
        check_pose_payload(p) for p in payloads
    ]  # the README table's decoder, checked against pose.json
    seqs = [d["seq"] for d in decoded]
    assert seqs == sorted(seqs), "poses arrived out of order"
    return len(set(seqs)) / (seqs[-1] - seqs[0] + 1), decoded


def test_subscriber_gets_95_percent_of_poses_decoded_with_the_documented_layout(daemon):
    # A subscriber that never reads is connected all along: it must not slow anyone.
    stalled = zmq.Context.instance().socket(zmq.SUB)
    stalled.rcvhwm = 10
    stalled.setsockopt(zmq.SUBSCRIBE, b"")
    stalled.connect(daemon.pub)
    try:
        payloads = collect_raw(daemon.pub, 2.0)
    finally:
        stalled.close(linger=0)
    coverage, poses = _coverage(payloads)
    assert coverage >= 0.95, f"only {coverage:.1%} of the poses arrived"
    span_s = (poses[-1]["publish_t_ns"] - poses[0]["publish_t_ns"]) / 1e9
    assert span_s > 1.5 and len(poses) > 500
    assert all(p["version"] == 1 and len(b) == 200 for p, b in zip(poses, payloads))
    limit = daemon_limits(daemon)["max_force_n"]
    for p in poses:
        assert p["flags"] < 32 and p["reserved"] == 0
        assert abs(np.linalg.norm(p["orientation"]) - 1.0) < 1e-9
        assert np.linalg.norm(p["force"]) <= limit + 1e-12
        assert np.all(np.isfinite(p["proxy"] + p["goal"] + p["tip"] + p["cube_center"]))
        assert (
            p["publish_t_ns"] >= p["device_t_ns"] or p["device_t_ns"] < 1e12
        )  # sim time or host time
    assert any(np.linalg.norm(p["force"]) > 0 for p in poses), "the arm never touched anything"


def daemon_limits(daemon) -> dict:
    with ControlClient(daemon.ctl) as client:
        return client.get_scene()["device"]["limits"]


def test_late_joiner_gets_the_scene_within_a_second(daemon):
    with Subscriber(daemon.pub) as sub:
        t0 = time.monotonic()
        scene = sub.wait_for_scene(3.0)
        assert time.monotonic() - t0 < 1.5
    assert scene["structure"]["n_atoms"] > 0 and scene["version"] == SCENE_VERSION


MALFORMED = [
    [b"\x00\x01\x02 garbage"],
    [b'{"cmd": "set", "args": {"stiffness_n_per_mm": "very"}}'],
    [b'{"cmd": "explode"}'],
    [b'{"cmd": "ping", "args": {"x": 1}}'],
    [b'{"cmd": "load", "args": {"path": "/nonexistent/file.pdb"}}'],
    [b'{"cmd": "load", "args": {"name": "junk"}}', b"this is not a structure file"],
    [b'{"cmd": "set", "args": {"stiffness_n_per_mm": 1000}}'],
    [b'{"cmd": "get_scene", "args": {}}', b"unexpected"],
    [b" " * (1 << 20)],
]


def _raw_request(endpoint: str, frames: list[bytes]):
    sock = zmq.Context.instance().socket(zmq.REQ)
    sock.linger = 0
    sock.connect(endpoint)
    try:
        sock.send_multipart(frames)
        assert sock.poll(15000), f"no reply to {frames[0][:60]!r}"
        reply = sock.recv_multipart()
        check_raw_reply(frames[0], reply)
        return decode_reply(reply)
    finally:
        sock.close()


def test_malformed_control_traffic_gets_errors_while_poses_keep_flowing(daemon):
    stop = threading.Event()
    result = {}
    thread = threading.Thread(
        target=lambda: result.setdefault("p", collect_raw(daemon.pub, 60, stop))
    )
    thread.start()
    try:
        time.sleep(0.3)
        for frames in MALFORMED:
            reply = _raw_request(daemon.ctl, frames)
            assert not reply.ok and reply.error and "\n" not in reply.error, frames[0][:60]
        _garbage_from_hypothesis(daemon.ctl)
        with ControlClient(daemon.ctl) as client:
            assert client.ping()["pong"] is True  # still serving
        time.sleep(0.3)
    finally:
        stop.set()
        join(thread)
    coverage, poses = _coverage(result["p"])
    assert coverage >= 0.95, f"only {coverage:.1%} of the poses arrived during the bad traffic"
    gaps = np.diff([p["publish_t_ns"] for p in poses]) / 1e9
    assert gaps.max() < 0.5, f"publishing stalled for {gaps.max():.2f} s"


def _garbage_from_hypothesis(endpoint: str) -> None:
    json_values = st.recursive(
        st.none() | st.booleans() | st.integers() | st.floats() | st.text(max_size=8),
        lambda c: st.lists(c, max_size=3) | st.dictionaries(st.text(max_size=8), c, max_size=3),
        max_leaves=8,
    )
    requests = st.one_of(
        st.lists(st.binary(max_size=64), min_size=1, max_size=3),
        st.builds(
            lambda cmd, args: [json.dumps({"cmd": cmd, "args": args}).encode()],
            st.sampled_from(["ping", "set", "load", "status", "record_stop", "nope", ""]),
            st.dictionaries(
                st.sampled_from(
                    [
                        "path",
                        "stiffness_n_per_mm",
                        "probe_radius_A",
                        "method",
                        "clip_planes",
                        "lights",
                        "reset_stats",
                        "x",
                    ]
                ),
                json_values,
                max_size=3,
            ),
        ),
    )

    @settings(
        max_examples=40, deadline=None, suppress_health_check=list(HealthCheck), database=None
    )
    @given(requests)
    def check(frames):
        reply = _raw_request(endpoint, frames)
        assert reply.ok or (reply.error and "\n" not in reply.error)
        if reply.ok:  # only well-formed, valid requests may succeed
            request = json.loads(frames[0])
            assert request["cmd"] in ("ping", "status", "set")

    check()


def test_control_commands_change_the_scene_and_serve_the_structure(daemon, tmp_path):
    with ControlClient(daemon.ctl) as client, Subscriber(daemon.pub) as sub:
        before = client.get_scene()
        result = client.set(
            stiffness_n_per_mm=0.2,
            clip_planes=[[0, 0, 1, 2.5]],
            lights={"probe": {"enabled": False}},
            nav_cube_enabled=False,
        )
        scene = client.get_scene()
        assert scene["revision"] > before["revision"] and result["seq"] > 0
        assert scene["haptics"]["stiffness_n_per_mm"] == 0.2
        assert (
            scene["clip_planes"] == [[0.0, 0.0, 1.0, 2.5]] and scene["nav_cube"]["enabled"] is False
        )
        assert scene["lights"]["probe"]["enabled"] is False
        assert scene["lights"]["directional"] == before["lights"]["directional"]
        deadline = time.monotonic() + 5
        while (
            sub.scene is None or sub.scene["revision"] < scene["revision"]
        ) and time.monotonic() < deadline:
            sub.poll(0.1)
        assert sub.scene["revision"] >= scene["revision"] and sub.malformed == 0
        status = client.status()
        assert status["publisher"]["subscribers"] >= 1 and status["loop"]["total"]["ticks"] > 0
    served = fetch_structure(daemon.ctl)
    structure = parse_structure(
        served.data, name=served.name, source=served.source, keep_water=served.keep_water
    )
    assert (
        structure.sha256 == scene["structure"]["sha256"]
        and structure.n_atoms == scene["structure"]["n_atoms"]
    )
    arrays = fetch_structure(daemon.ctl, form="arrays")  # the same atoms, parsed by the daemon
    unpacked = unpack_structure(arrays.data, arrays.name, arrays.source, arrays.sha256)
    assert arrays.form == "arrays" and unpacked.sha256 == structure.sha256
    assert np.array_equal(unpacked.positions, structure.positions)
    assert np.array_equal(unpacked.atom_names, structure.atom_names)


def test_load_by_bytes_switches_the_structure(daemon, reference_by_id):
    data = reference_by_id["1oky"].path.read_bytes()
    with ControlClient(daemon.ctl) as client:
        old = client.get_scene()["structure"]
        result = client.load(data=data, name="1oky.pdb.gz")  # named as a file: the name is its stem
        assert result["structure"]["n_atoms"] > 2000 and result["structure"]["name"] == "1oky"
        assert client.get_scene()["structure"]["name"] == "1oky"
        header, raw = client.get_structure()
        assert raw == data and header["sha256"] != old["sha256"] and header["name"] == "1oky"
        with pytest.raises(ControlError, match="load"):
            client.load(data=b"\x1f\x8b not really gzip", name="bad")
        client.load(data=fetch_raw_default(), name=old["name"])


def fetch_raw_default() -> bytes:
    from sasprobe.molecule import load_default

    return load_default().source_bytes


def _holding_clutch(endpoint: str, held: threading.Event, stop: threading.Event) -> None:
    """The window's clutch key held down: `clutch` re-sent within its 1 s lease until `stop`
    (`held` is set once the daemon has taken the first)."""
    with ControlClient(endpoint) as client:
        while not stop.is_set():
            client.call("clutch", held=True)
            held.set()
            stop.wait(0.2)


def test_recording_started_mid_session_replays_exactly(daemon):
    """Started with the view turned and the clutch held, a recording opens with both (at the
    start's tick) and replays exactly; a structure loaded as bytes named `1crn.pdb.gz` is
    recorded, and attached, under its stem."""
    path = daemon.sockets / "mid.mcap"
    turn = [[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]]
    held, stop_clutch = threading.Event(), threading.Event()
    clutch = threading.Thread(target=_holding_clutch, args=(daemon.ctl, held, stop_clutch))
    with ControlClient(daemon.ctl) as client:
        with pytest.raises(ControlError, match="not recording"):
            client.record_stop()
        client.call("view", rotation=turn)
        clutch.start()
        try:
            assert held.wait(30), "the clutch was not taken"
            started = client.record_start("mid.mcap")  # below its --record-dir
        finally:
            stop_clutch.set()
            join(clutch)
        client.call("clutch", held=False)
        with pytest.raises(ControlError, match="already recording"):
            client.record_start("second.mcap")
        time.sleep(0.6)
        client.set(damping_n_s_per_m=0.3, method="penalty")
        time.sleep(0.6)
        client.set(method="proxy")
        loaded = client.load(
            data=fetch_raw_default(), name="1crn.pdb.gz"
        )  # the module's structure again
        time.sleep(0.3)
        stopped = client.record_stop()
        client.call("view", rotation=[[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]])
    assert stopped["dropped"] == 0 and stopped["path"] == str(path) and started["seq"] > 0
    assert loaded["structure"]["name"] == "1crn"
    items = list(iter_items(path))  # every record checked against the schemas as it is read
    control = [item.data for item in items if item.topic == "control"]
    assert [(c["cmd"], c["seq"]) for c in control[:3]] == [
        ("start", started["seq"]),
        ("view", started["seq"]),
        ("clutch", started["seq"]),
    ]
    assert control[1]["args"]["rotation"] == turn and control[2]["args"] == {"held": True}
    assert [c["cmd"] for c in control[3:]] == ["clutch", "set", "set", "load", "record_stop"]
    (load,) = [c for c in control if c["cmd"] == "load"]
    assert (
        load["args"]["name"] == "1crn" and load["args"]["sha256"] == loaded["structure"]["sha256"]
    )
    attachments = [item.data["name"] for item in items if item.topic == "attachment"]
    assert attachments == ["1crn"]  # at the start; the load of the same bytes adds none
    out = run_cli("replay", str(path), "--verify", "--json")
    verify = json.loads(out.stdout)["verify"]
    assert out.returncode == 0 and verify["ok"] and verify["events_applied"] >= 4, out.stdout


def test_status_command_prints_rate_jitter_and_subscribers(daemon):
    out, js, gone = cli_many(
        ("status", "--ctl", daemon.ctl),
        ("status", "--ctl", daemon.ctl, "--json"),
        ("status", "--ctl", "ipc:///tmp/sasprobe-nobody-here", "--timeout", "0.5"),
    )
    assert out.returncode == 0, out.stderr
    for word in ("rate", "jitter", "overruns", "subscriber", "recording"):
        assert word in out.stdout
    js = json.loads(js.stdout)
    assert (
        js["loop"]["target_rate_hz"] == 1000.0 and js["loop"]["period_error_us"]["p50"] is not None
    )
    assert gone.returncode == 2 and "no reply" in gone.stderr and gone.stderr.count("\n") == 1


def test_non_loopback_bind_without_keys_is_refused():
    out = run_cli("daemon", "--pub", "tcp://0.0.0.0:45555", "--seconds", "1")
    assert out.returncode == 2
    assert out.stderr.startswith(
        "sasprobe: error: refusing to bind tcp://0.0.0.0:45555 without encryption"
    )
    assert out.stderr.count("\n") == 1


def test_curve_keys_admit_allowed_clients_and_reject_unknown_ones(tmp_path, gl):
    """A keyed daemon: status and a renderer with the keys follow it; a client whose key is not
    allowed, or who has none, gets one line saying so (and the daemon logs the refusal)."""
    keys, other = tmp_path / "keys", tmp_path / "other"
    assert run_cli("keys", str(keys)).returncode == 0
    assert run_cli("keys", str(other)).returncode == 0
    (other / "server.key").write_bytes((keys / "server.key").read_bytes())
    pub_port, ctl_port = free_port(), free_port()
    with DaemonProcess(
        "--keys", str(keys), pub=f"tcp://0.0.0.0:{pub_port}", ctl=f"tcp://0.0.0.0:{ctl_port}"
    ) as d:
        pub, ctl = f"tcp://127.0.0.1:{pub_port}", f"tcp://127.0.0.1:{ctl_port}"
        from sasprobe.protocol.security import load_client_keys

        with Subscriber(pub, keys=load_client_keys(keys)) as sub:
            sub.wait_for_scene(5.0)
        render = (
            "render",
            "--headless",
            "--connect",
            pub,
            "--control",
            ctl,
            "--frames",
            "2",
            "--size",
            "64x48",
            "--out",
            str(tmp_path / "followed.mp4"),
        )
        ok, followed, rejected, plain, refused_render = cli_many(
            ("status", "--ctl", ctl, "--keys", str(keys), "--json"),
            (*render, "--keys", str(keys)),
            ("status", "--ctl", ctl, "--keys", str(other), "--timeout", "1"),
            ("status", "--ctl", ctl, "--timeout", "1"),
            (*render, "--keys", str(other)),
        )
        assert ok.returncode == 0, ok.stderr
        assert followed.returncode == 0, followed.stderr  # render --keys follows the keyed daemon
        for out in (rejected, refused_render):
            assert out.returncode == 2 and out.stderr.count("\n") == 1, out.stderr
            assert "refused this client's CURVE key" in out.stderr, out.stderr
        # no --keys on loopback: this user's local keys, whose server key is not this daemon's
        assert plain.returncode == 2 and "give the same --keys DIR" in plain.stderr, plain.stderr
        rc, _ = d.stop()
    assert rc == 0
    assert "refused a client whose CURVE public key" in d.stderr  # the daemon's side of it


def test_user_errors_end_in_one_line(tmp_path):
    import socket

    existing = tmp_path / "old.mcap"
    existing.write_bytes(b"")
    with socket.socket() as busy:
        busy.bind(("127.0.0.1", 0))
        busy.listen()
        port = busy.getsockname()[1]
        cases = {
            "is a daemon already running there?": (
                "daemon",
                "--pub",
                f"tcp://127.0.0.1:{port}",
                "--ctl",
                f"ipc://{tmp_path}/c",
            ),
            "already exists": ("daemon", "--record", str(existing)),
            "unknown device": ("daemon", "--device", "warp:9"),
            "stiffness must be": ("daemon", "--stiffness", "50"),
            "no such file": ("daemon", "--device", f"replay:{tmp_path}/none.mcap"),
            "not an MCAP file": ("replay", str(existing)),
        }
        outs = cli_many(
            *[(*args, "--seconds", "1") if args[0] == "daemon" else args for args in cases.values()]
        )
    for fragment, out in zip(cases, outs):
        assert out.returncode == 2, (fragment, out.stderr)
        assert (
            fragment in out.stderr and out.stderr.count("\n") == 1 and "Traceback" not in out.stderr
        ), out.stderr
