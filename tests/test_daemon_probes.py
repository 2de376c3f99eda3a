"""The real daemon probed as an attacker or a careless script would: each probe is
answered with an error or dropped, the control server answers afterwards, and the loop
does not stall while it happens.

The pose gaps come from tests/support/pose_watch.py, a process of its own, which also notes the
machine's own pauses (a VM's stolen time stalls every process): a probe passes when the
part of its longest pose gap that such a pause does not explain is under LIMIT_MS (20 ms;
60 ms when the daemon could not get real-time scheduling, where ordinary
preemption alone takes several ms). Unprotected, these probes stalled the loop 0.3-2 s.
"""

from __future__ import annotations

import gzip
import os
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest
import zmq
from sasprobe.protocol.client import ControlClient
from sasprobe.protocol.control import MAX_MESSAGE_BYTES, decode_reply, encode_request

from tests.support.bounded import join
from tests.support.daemon_process import DaemonProcess
from tests.support.probe import PoseWatch, now_ns, unexplained_ms
from tests.support.schema_check import check_raw_reply

LIMIT_MS = {True: 20.0, False: 60.0}  # by whether the daemon runs under SCHED_FIFO
SETTLE_S = 0.3  # a probe's window extends this far past its reply (a stall right after it counts)


@pytest.fixture(scope="module")
def setup(tmp_path_factory, reference_by_id):
    root = tmp_path_factory.mktemp("probes")
    loads, records = root / "loads", root / "records"
    loads.mkdir()
    records.mkdir()
    (loads / "crambin.pdb.gz").write_bytes(reference_by_id["1crn"].path.read_bytes())
    os.mkfifo(loads / "pipe.pdb")
    (loads / "passwd.pdb").symlink_to("/etc/passwd")
    (records / "out").symlink_to(root)
    with (
        DaemonProcess("--load-dir", str(loads), "--record-dir", str(records)) as daemon,
        PoseWatch(daemon.pub) as w,
    ):
        yield daemon, w, records, reference_by_id


def _raw(daemon, frames: list, timeout_s: float = 20.0, kind=zmq.REQ):
    sock = zmq.Context.instance().socket(kind)
    sock.linger = 0
    sock.connect(daemon.ctl)
    try:
        sock.send_multipart(frames, copy=False)
        if not sock.poll(int(timeout_s * 1000)):
            return None
        reply = sock.recv_multipart()
        check_raw_reply(frames[0], reply)
        return decode_reply(reply)
    finally:
        sock.close()


def _rss_mb(pid: int) -> float:
    for line in Path(f"/proc/{pid}/status").read_text().splitlines():
        if line.startswith("VmRSS:"):
            return int(line.split()[1]) / 1024
    return 0.0


def _subscribers(daemon) -> int:
    with ControlClient(daemon.ctl) as client:
        return client.status()["publisher"]["subscribers"]


def test_probes_are_answered_and_do_not_stall_the_loop(setup):
    daemon, watch, records, shared = setup
    windows: list[tuple[str, int, int]] = []
    actions: dict = {}  # name -> (action, fragments): each probe can run again
    pid = daemon.proc.pid

    def probe(name: str, action, *fragments: str, into: list | None = None) -> None:
        actions[name] = (action, *fragments)
        t0 = now_ns()
        reply = action()
        t1 = now_ns()
        if fragments:
            assert reply is not None and not reply.ok, f"{name}: {reply}"
            assert all(f in reply.error for f in fragments) and "\n" not in reply.error, (
                f"{name}: {reply.error}"
            )
        with ControlClient(daemon.ctl, timeout_s=5) as client:
            assert client.ping()["pong"], f"the control server stopped answering after {name}"
        (windows if into is None else into).append((name, t0, t1 + int(SETTLE_S * 1e9)))

    probe("inf id", lambda: _raw(daemon, [b'{"cmd": "ping", "id": 1e400}']), "not finite")
    probe(
        "401-digit integer",
        lambda: _raw(daemon, [b'{"cmd": "ping", "id": ' + b"9" * 401 + b"}"]),
        "401 digits",
    )
    probe(
        "20,000-deep nesting",
        lambda: _raw(daemon, [b'{"cmd": "ping", "id": ' + b"[" * 20000 + b"]" * 20000 + b"}"]),
        "deeper than",
    )
    probe("1 MiB request", lambda: _raw(daemon, [b" " * (1 << 20)]), "larger than")
    half = MAX_MESSAGE_BYTES // 2 + 1  # two of these and the JSON: just over the limit
    probe(
        "3-frame message over the limit",
        lambda: _raw(daemon, [b'{"cmd": "load"}', *[bytes(half)] * 2]),
        "in 3 frames",
    )

    # The publisher: a 16 MiB subscription (the trie once cost 110 B per topic byte, on the loop).
    # In a process of its own: libzmq 4.3.5 crashes closing a SUB whose 16 MiB subscription the
    # peer keeps refusing (the attacker's side; the daemon is unharmed), so it exits unclosed.
    rss = _rss_mb(pid)
    attacker = [
        sys.executable,
        "-c",
        "import os, sys, time, zmq; s = zmq.Context().socket(zmq.SUB); "
        "s.setsockopt(zmq.SUBSCRIBE, b'p' * (16 << 20)); s.connect(sys.argv[1]); time.sleep(1.0); "
        "os._exit(0)",
        daemon.pub,
    ]
    probe("16 MiB subscription", lambda: subprocess.run(attacker, timeout=60) and None)
    assert _rss_mb(pid) - rss < 64, (
        f"the daemon grew by {_rss_mb(pid) - rss:.0f} MB for one subscription"
    )

    # Raw subscription frames cannot forge the subscriber count, either way.
    before = _subscribers(daemon)
    forgers = []
    for flag in (1, 0):
        xsub = zmq.Context.instance().socket(zmq.XSUB)
        xsub.linger = 0
        xsub.connect(daemon.pub)
        for _ in range(100):
            xsub.send(bytes([flag]) + b"pose")
        forgers.append(xsub)
    time.sleep(0.5)
    assert _subscribers(daemon) == before + 2  # two peers, however many frames they sent
    for xsub in forgers:
        xsub.close()

    bomb = (
        gzip.compress(bytes(1 << 20), 9) * 1024
    )  # 1,024 gzip members of 1 MiB of zeros: 1 MiB -> 1 GiB
    probe(
        "gzip bomb",
        lambda: _raw(daemon, [encode_request("load", {"name": "bomb"})[0], bomb]),
        "inflates beyond",
    )
    for path in ("/etc/passwd", "../crambin.pdb.gz", "passwd.pdb"):
        probe(
            f"load path {path}",
            lambda path=path: _raw(daemon, encode_request("load", {"path": path})),
            "not below",
        )
    probe(
        "load a FIFO",
        lambda: _raw(daemon, encode_request("load", {"path": "pipe.pdb"})),
        "is a FIFO",
    )
    loaded = _raw(daemon, encode_request("load", {"path": "crambin.pdb.gz"}))
    assert loaded.ok and loaded.result["structure"]["n_atoms"] == 327  # the opt-in folder works
    for path in ("/tmp/x.mcap", "../x.mcap", "out/x.mcap"):
        probe(
            f"record_start {path}",
            lambda path=path: _raw(daemon, encode_request("record_start", {"path": path})),
            "not below",
        )
    started = _raw(daemon, encode_request("record_start", {"path": "ok.mcap"}))
    assert started.ok and (records / "ok.mcap").stat().st_mode & 0o777 == 0o600
    assert _raw(daemon, encode_request("record_stop")).ok

    reply = _raw(
        daemon, [b'{"cmd": "ping"}', b""], kind=zmq.DEALER
    )  # a DEALER's empty frame: framed right
    assert reply is not None and not reply.ok and "no data frame" in reply.error

    big = shared["6zu5"].path.read_bytes()
    probe(
        "load 6ZU5 (165k atoms)",
        lambda: _raw(daemon, [encode_request("load", {"name": "6zu5"})[0], big], 120),
    )
    assert _raw(
        daemon, [encode_request("load", {"name": "1crn"})[0], shared["1crn"].path.read_bytes()]
    ).ok

    result = watch.finish()
    assert result["poses"] > 1000
    limit = LIMIT_MS[bool(daemon.ready.get("realtime"))]
    stalled = _stalls(result, windows, limit)
    if stalled:
        # A probe that stalls the loop does so every time it runs (unprotected, each of these
        # took 0.3-2 s, run after run). A stall from elsewhere does not follow the probe: on
        # one machine, stalls of 110 and 22 ms fell across the burst of quick path probes and
        # one of 234 ms on the 16 MiB subscription, in 2 of 8 runs (CI once saw 24 ms on the
        # 6ZU5 load), yet 6 runs of the subscription alone and 3 of the path probes stalled
        # nothing. So a probe whose window held a stall runs once more, alone, watched
        # afresh, and fails if the loop stalls again.
        again: list = []
        with PoseWatch(daemon.pub) as watch_again:
            for name in stalled:
                probe(name, *actions[name], into=again)
                time.sleep(SETTLE_S)  # windows that do not overlap
            second = watch_again.finish()
        still = _stalls(second, again, limit)
        assert not still, f"the loop stalled ≥ {limit:g} ms during, twice: " + ", ".join(
            f"{name} ({stalled[name]:.1f} and {rest:.1f} ms)" for name, rest in still.items()
        )


def _stalls(result: dict, windows: list, limit_ms: float) -> dict[str, float]:
    """Each probe's longest pose gap a machine pause does not explain, printed; those ≥ the
    limit."""
    print("\nprobe: longest pose gap / not explained by a machine pause (ms)")
    stalled = {}
    for name, start, end in windows:
        longest, rest = unexplained_ms(result, start, end)
        print(f"  {name}: {longest:.1f} / {rest:.1f}")
        if rest >= limit_ms:
            stalled[name] = rest
    return stalled


def test_the_pose_watcher_checks_every_pose(tmp_path):
    """tests/support/pose_watch.py reports a pose that breaks pose.json (here a reserved word
    that is not 0), and PoseWatch fails the test that used it."""
    from sasprobe.protocol.pose import Pose, encode_pose

    bad = bytearray(encode_pose(Pose(seq=1)))
    bad[164] = 1  # the reserved word
    pub = zmq.Context.instance().socket(zmq.PUB)
    pub.linger = 0
    endpoint = f"ipc://{tmp_path}/pub"
    pub.bind(endpoint)
    stop = threading.Event()

    def publish() -> None:
        while not stop.is_set():
            pub.send_multipart([b"pose", bytes(bad)])
            stop.wait(0.001)

    sender = threading.Thread(target=publish)
    sender.start()
    try:
        watch = PoseWatch(endpoint)
    finally:
        stop.set()
        join(sender)
        pub.close()
    with pytest.raises(AssertionError, match="broke the protocol"):
        watch.finish()
    assert watch.result["invalid"] >= 1 and "'reserved': 1" in watch.result["why"][0]
