"""Local access: key and socket files private whatever the umask, ipc paths never replaced, the
local key folder checked; the publisher renewed by a subscription flood; running out of file
descriptors; real-time scheduling refused and ticks being lost, each said once."""

from __future__ import annotations

import logging
import os
import socket
import stat
import subprocess
import time

import pytest
import zmq
from sasprobe.daemon.faults import LoopLog
from sasprobe.daemon.publisher import MAX_FOREIGN_SUBSCRIPTIONS, Publisher
from sasprobe.daemon.realtime import enter_realtime
from sasprobe.protocol.client import ControlClient, Subscriber
from sasprobe.protocol.pose import Pose, encode_pose
from sasprobe.protocol.security import KeyFileError, ensure_local_keys, generate_keys

from sasprobe.common.errors import UserError
from tests.support.daemon_process import DaemonProcess


@pytest.fixture
def open_umask():
    old = os.umask(0)
    yield
    os.umask(old)


def _mode(path) -> int:
    return stat.S_IMODE(os.lstat(path).st_mode)


def test_keys_and_sockets_are_private_under_umask_000(tmp_path, open_umask):
    generate_keys(tmp_path / "keys")
    assert (
        _mode(tmp_path / "keys") == 0o700 and _mode(tmp_path / "keys" / "allowed_clients") == 0o700
    )
    assert _mode(tmp_path / "keys" / "server.key_secret") == 0o600
    assert (
        _mode(tmp_path / "keys" / "allowed_clients" / "client.key") == 0o644
    )  # public, but nobody else writes it
    context = zmq.Context()
    pub = Publisher(context, [f"ipc://{tmp_path}/pub"])
    try:
        assert (
            _mode(tmp_path / "pub") & 0o077 == 0
        )  # connecting needs write permission: only the owner has it
    finally:
        pub.close()
        context.term()


def test_an_ipc_path_is_never_replaced(tmp_path):
    (tmp_path / "notes.txt").write_text("keep me")
    live = socket.socket(socket.AF_UNIX)
    live.bind(str(tmp_path / "live"))
    live.listen()
    context = zmq.Context()
    try:
        for name, why in (
            ("notes.txt", "is not a socket"),
            ("live", "another process is listening"),
        ):
            with pytest.raises(UserError, match=why):
                Publisher(context, [f"ipc://{tmp_path}/{name}"])
        assert (tmp_path / "notes.txt").read_text() == "keep me"
        live.close()  # now a dead socket file: binding takes it over
        Publisher(context, [f"ipc://{tmp_path}/live"]).close()
    finally:
        live.close()
        context.term()


def test_the_local_key_folder_must_be_private(tmp_path, monkeypatch, open_umask):
    monkeypatch.setenv("XDG_RUNTIME_DIR", str(tmp_path / "run"))
    folder = ensure_local_keys()
    assert folder == tmp_path / "run" / "sasprobe" and _mode(folder) == 0o700
    assert (
        _mode(folder / "client.key_secret") == 0o600 and ensure_local_keys() == folder
    )  # made once
    os.chmod(folder, 0o777)
    with pytest.raises(KeyFileError, match="only you can use"):
        ensure_local_keys()


def test_a_subscription_flood_renews_the_publisher(tmp_path):
    context = zmq.Context()
    endpoint = f"ipc://{tmp_path}/pub"
    pub = Publisher(context, [endpoint])
    flood = context.socket(zmq.XSUB)
    flood.linger = 0
    flood.connect(endpoint)
    sub = Subscriber(endpoint, context=context)
    try:
        seq, deadline = 0, time.monotonic() + 20
        sent = 0
        while pub.renewals == 0 and time.monotonic() < deadline:
            for _ in range(64):
                flood.send(b"\x01junk-%d" % sent, zmq.NOBLOCK)
                sent += 1
            pub.poll_subscriptions()
            pub.publish_pose(encode_pose(Pose(seq=seq)))
            seq += 1
            time.sleep(0.001)
        assert pub.renewals == 1 and sent > MAX_FOREIGN_SUBSCRIPTIONS
        flood.close()
        before = sub.poses_received
        while (
            sub.poses_received == before and time.monotonic() < deadline
        ):  # the subscriber comes back by itself
            pub.poll_subscriptions()
            pub.publish_pose(encode_pose(Pose(seq=seq)))
            seq += 1
            sub.poll(0.01)
        assert sub.poses_received > before
    finally:
        sub.close()
        pub.close()
        context.term()


def _thread_cpu_s(pid: int, name: str) -> float:
    total = 0.0
    for task in os.listdir(f"/proc/{pid}/task"):
        try:
            with open(f"/proc/{pid}/task/{task}/stat") as f:
                fields = f.read().rsplit(")", 1)[1].split()
            with open(f"/proc/{pid}/task/{task}/comm") as f:
                comm = f.read().strip()
        except OSError:
            continue
        if comm.startswith(name):
            total += (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")
    return total


def test_running_out_of_file_descriptors_is_said_and_survived(tmp_path):
    """A daemon with 64 descriptors and a client holding 100 connections to its control port:
    the daemon says so, ZeroMQ's I/O thread does not spin on the failing accept(), and control
    answers again once the connections are gone."""
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    ctl = f"tcp://127.0.0.1:{port}"
    with DaemonProcess("--no-realtime", ctl=ctl) as daemon:
        subprocess.run(
            ["prlimit", f"--pid={daemon.proc.pid}", "--nofile=64:64"], check=True, timeout=30
        )
        holders = []
        for _ in range(100):
            c = socket.socket()
            c.connect(("127.0.0.1", port))
            holders.append(c)
        time.sleep(0.5)
        cpu0 = _thread_cpu_s(daemon.proc.pid, "ZMQbg/IO")
        time.sleep(1.0)
        spin = _thread_cpu_s(daemon.proc.pid, "ZMQbg/IO") - cpu0
        for c in holders:
            c.close()
        with ControlClient(ctl, timeout_s=10) as client:
            assert client.ping()["pong"]  # accepting again
        assert spin < 0.5, f"ZeroMQ's I/O thread used {spin:.2f} s of CPU in 1 s"
        assert "cannot accept connections: Too many open files" in daemon.stderr


def test_refused_real_time_scheduling_is_one_line_with_the_fix(monkeypatch, caplog):
    def refuse(*args):
        raise PermissionError(1, "Operation not permitted")

    monkeypatch.setattr(os, "sched_setscheduler", refuse)
    with caplog.at_level(logging.WARNING, logger="sasprobe"):
        assert enter_realtime() is False
    lines = [r.getMessage() for r in caplog.records]
    assert len(lines) == 1 and "real-time scheduling refused (Operation not permitted)" in lines[0]
    assert "rtprio" in lines[0] and "CAP_SYS_NICE" in lines[0] and "--no-realtime" in lines[0]


def test_lost_ticks_are_told_once(caplog):
    log = LoopLog(realtime=False)
    with caplog.at_level(logging.WARNING, logger="sasprobe"):
        for i in range(5000):
            log.lost_ticks(
                i * 1_000_000, 1 if i % 3 == 0 else 0
            )  # a third of the ticks lost, for 5 s
    lines = [r.getMessage() for r in caplog.records]
    assert len(lines) == 1 and "losing ticks" in lines[0] and "real-time" in lines[0]
    assert log.lost == 1667


def test_a_cleared_fault_is_named_and_an_untold_one_is_not_cleared(caplog):
    """The log's fault lines: a fault and its end name the fault, even when the rate limit
    kept the fault's own line back; a timing fault (told by the lost-ticks line) gets no
    'cleared' line of its own."""

    class Guard:
        def __init__(self, fault: bool, reason: str | None = None) -> None:
            self.fault, self.reason = fault, reason

    ms = 1_000_000
    log = LoopLog(realtime=False)
    read = "device read failed: device read took 4.5 ms"
    steps = [  # (tick time, timing only, guard after the tick)
        (0, True, Guard(True, "the tick started 3.0 periods late")),
        (1 * ms, False, Guard(False)),
        (2000 * ms, False, Guard(True, read)),
        (2001 * ms, False, Guard(False)),  # within a second of the last line: held back
        (2002 * ms, False, Guard(True, read)),  # held back too
        (3500 * ms, False, Guard(False)),
    ]
    with caplog.at_level(logging.WARNING, logger="sasprobe"):
        for now, timing_only, guard in steps:
            log.tick(now, 0, timing_only, True, guard, None)
    assert [r.getMessage() for r in caplog.records] == [
        f"device fault: {read}; force zeroed",
        f"device fault cleared ({read}), force back on (2 more in the last second)",
    ]
