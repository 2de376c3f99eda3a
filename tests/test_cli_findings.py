"""`sasprobe findings DIR` when the daemon stops during the analysis: one line that says the
daemon closed the connection and that its analysis goes on, from a stand-in daemon that
answers `findings` and then closes its control socket as a stopping daemon does."""

from __future__ import annotations

import threading

import zmq
from sasprobe.protocol.control import ControlReply, decode_request, encode_reply

from tests.conftest import run_cli


def test_the_daemon_going_away_is_one_line(tmp_path):
    endpoint = f"ipc://{tmp_path}/ctl"
    context = zmq.Context()
    server = context.socket(zmq.REP)
    server.linger = 0
    server.bind(endpoint)
    asked: list[str] = []

    def serve() -> None:
        request = decode_request(server.recv_multipart())
        asked.append(request.cmd)
        job = {"dir": "live", "recording": "s.mcap", "state": "running", "pid": 4242}
        server.send_multipart(encode_reply(ControlReply(True, job, id=request.id)))
        if server.poll(60_000):  # the first status request: the daemon stops instead
            asked.append(decode_request(server.recv_multipart()).cmd)
        server.close(linger=0)

    thread = threading.Thread(target=serve, daemon=True)
    thread.start()
    try:
        r = run_cli("findings", "live", "--ctl", endpoint, timeout=120)
    finally:
        thread.join(timeout=60)
        context.term()
    assert asked == ["findings", "status"]
    assert r.returncode == 2 and r.stdout == ""
    line = r.stderr.replace("\r", "\n").strip().splitlines()[-1]
    assert line == (
        f"sasprobe: error: findings: no reply from the daemon at {endpoint} within 3 s: the "
        f"daemon at {endpoint} closed the connection (it stopped?); the analysis (pid 4242) "
        "still writes live/ on the daemon's host"
    ), r.stderr
    assert "Traceback" not in r.stderr
