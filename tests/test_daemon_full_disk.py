"""A recording whose disk fills up: the daemon goes on as before and says so, and everything
recorded before the failure replays. The full disk is the daemon's own file-size limit
(RLIMIT_FSIZE, set on the running daemon with prlimit): a write past it fails with EFBIG
(Python ignores SIGXFSZ), as a write to a full filesystem fails with ENOSPC, without
needing a filesystem of our own."""

from __future__ import annotations

import json
import resource
import time

import numpy as np
from sasprobe.protocol.client import ControlClient, Subscriber

from tests.conftest import run_cli
from tests.support.daemon_process import DaemonProcess
from tests.support.recordings import reference_ticks

ROOM_BYTES = 64 << 10  # what the recording may still grow by: a fraction of a second
EFBIG = "OSError: [Errno 27] File too large"


def _until(condition, what: str, timeout_s: float = 60.0):
    deadline = time.monotonic() + timeout_s
    while not (value := condition()):
        assert time.monotonic() < deadline, f"{what} not within {timeout_s:g} s"
        time.sleep(0.05)
    return value


def _ticks(client: ControlClient) -> int:
    return client.status()["loop"]["total"]["ticks"]


def _recording(client: ControlClient, name: str) -> None:
    client.record_start(name)  # below --record-dir
    _until(lambda: client.status()["recording"]["bytes"] > 20_000, f"{name} under way")


def _pressed(pub: str) -> None:
    """Wait until the simulated hand presses the surface (a pose with force)."""
    sub = Subscriber(pub)
    try:
        _until(lambda: any(np.any(p.force_N) for p in sub.poll(0.1)), "a pose with force", 120.0)
    finally:
        sub.close()


def test_a_full_disk_fails_the_recording_and_nothing_else(tmp_path):
    path, again = tmp_path / "full.mcap", tmp_path / "again.mcap"
    daemon = DaemonProcess("--record-dir", str(tmp_path))
    with daemon as d, ControlClient(d.ctl, timeout_s=30) as client:
        pid = d.proc.pid
        _recording(client, path.name)
        _pressed(d.pub)  # a force in the recording: its replay then checks a contact too
        status = client.status()
        ticks = status["loop"]["total"]["ticks"]  # the recording holds these by now
        room = status["recording"]["bytes"] + ROOM_BYTES
        resource.prlimit(pid, resource.RLIMIT_FSIZE, (room, resource.RLIM_INFINITY))
        failed = _until(lambda: client.status()["recording"]["error"], "the write failure")
        # The loop goes on: a thousand ticks more (counted, not timed: a busy machine is slow).
        since = _ticks(client)
        _until(lambda: _ticks(client) >= since + 1000, "1000 ticks after the failure")
        device = client.status()["device"]
        shown = run_cli("status", "--ctl", d.ctl)
        resource.prlimit(pid, resource.RLIMIT_FSIZE, (resource.RLIM_INFINITY,) * 2)
        client.record_stop()
        _recording(client, again.name)  # the daemon records again once there is room
        client.record_stop()
        rc, report = d.stop()

    assert failed == EFBIG, failed
    assert shown.returncode == 0 and f"FAILED: {EFBIG}" in shown.stdout, shown.stdout
    warnings = [line for line in d.stderr.splitlines() if "recording to" in line]
    assert len(warnings) == 1 and f"recording to {path} failed: {EFBIG}" in warnings[0], warnings
    assert rc == 0, d.stderr
    # The writer thread's failure is not the device's: every force written, and no fault of
    # the device's names it (a busy machine may fault a tick that came late: not this one's to
    # count).
    assert device["write_failures"] == 0, device
    assert "Errno" not in (device["last_fault"] or ""), device["last_fault"]

    # Everything before the failure is in the file, in order, and replays to the same forces
    # (read as the README's tables lay the ticks out).
    recorded = reference_ticks(path, cut=True)
    seqs = [t["pose"]["seq"] for t in recorded]
    assert seqs == list(range(seqs[0], seqs[0] + len(seqs))) and seqs[-1] >= ticks
    for recording in (path, again):
        out = run_cli("replay", str(recording), "--verify", "--json", timeout=300)
        assert out.returncode == 0, out.stderr
        verify = json.loads(out.stdout)["verify"]
        assert verify["ok"] and verify["max_force_diff_n"] == 0.0, verify
    # The forces before it pressed the surface, and the device answered every read throughout
    # (ticks a busy machine makes late are zeroed by the loop's own rule, which the replays
    # reproduce).
    second = reference_ticks(again)
    assert max(np.linalg.norm(t["pose"]["force"]) for t in recorded) > 0.0
    assert not any(t["error"] for t in recorded + second)
