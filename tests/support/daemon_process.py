"""Run `sasprobe` as real subprocesses: several commands at once, or the daemon on private sockets
(one command: conftest.run_cli); free loopback ports for a daemon's sockets, and its poses read
on a raw ZeroMQ socket."""

from __future__ import annotations

import os
import shutil
import signal
import socket
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

import zmq

from sasprobe.cli.children import DaemonChild
from sasprobe.common.errors import UserError
from tests.conftest import REPO_ROOT
from tests.support.schema_check import assert_valid

CLI = [sys.executable, "-m", "sasprobe"]
DEVICE = "sim"


def cli_many(*commands: tuple[str, ...], timeout: float = 120) -> list[subprocess.CompletedProcess]:
    """Run several `sasprobe` commands at once (start-up dominates short ones)."""
    procs = [
        subprocess.Popen(
            [*CLI, *args],
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            text=True,
            cwd=REPO_ROOT,
            env=dict(os.environ, PYTHONUNBUFFERED="1"),
        )
        for args in commands
    ]
    results = []
    for args, proc in zip(commands, procs):
        out, err = proc.communicate(timeout=timeout)
        results.append(subprocess.CompletedProcess([*CLI, *args], proc.returncode, out, err))
    return results


class DaemonProcess:
    """The daemon as the tests use it: sasprobe.cli.children.DaemonChild on ipc:// sockets in a
    private folder that is also its working directory (nothing a test asks it to write lands
    in the checkout); AssertionError with its stderr when it does not become ready. Its
    stdout events are checked against protocol/schemas/events.schema.json; `left_behind`
    lists what the folder held once it stopped."""

    def __init__(
        self,
        *args: str,
        device: str = DEVICE,
        pub: str | None = None,
        ctl: str | None = None,
        ready_timeout: float = 90.0,
    ) -> None:
        self.sockets = Path(
            tempfile.mkdtemp(prefix="spd")
        )  # short: ipc paths are limited to ~100 bytes
        self.pub = pub or f"ipc://{self.sockets}/pub"
        self.ctl = ctl or f"ipc://{self.sockets}/ctl"
        self._stderr: str | None = None  # kept once the private folder is gone
        self.left_behind: list[str] | None = None  # the folder's names after the daemon stopped
        self.child = DaemonChild(
            ["--device", device, "--pub", self.pub, "--ctl", self.ctl, *args],
            self.sockets / "daemon.log",
            cwd=self.sockets,
        )
        self.proc = self.child.proc
        try:
            self.ready = self.child.wait_ready(ready_timeout)
        except UserError as exc:
            self._cleanup()
            raise AssertionError(f"{exc}; stderr: {self.stderr}") from None
        assert_valid("events", self.ready)

    @property
    def stderr(self) -> str:
        if self._stderr is not None:
            return self._stderr
        try:
            return self.child.log_path.read_text(errors="replace")
        except OSError:
            return ""

    def stop(self, sig: int = signal.SIGTERM, timeout: float = 30.0) -> tuple[int, dict | None]:
        """Signal the daemon, wait for it, return (exit status, exit report or None)."""
        rc = self.child.stop(timeout, sig)
        report = self.child.exit_report
        if report is not None:
            assert_valid("events", report)
        self.left_behind = sorted(os.listdir(self.sockets))
        self._cleanup()
        return rc, report

    def _cleanup(self) -> None:
        if self.child.alive():
            self.child.kill_group()
        self.child.finish(0)
        self._stderr = self.stderr
        shutil.rmtree(self.sockets, ignore_errors=True)

    def __enter__(self) -> DaemonProcess:
        return self

    def __exit__(self, *exc) -> None:
        self._cleanup()


def free_port() -> int:
    """A loopback TCP port that was free a moment ago."""
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def free_tcp_endpoint() -> str:
    """A loopback TCP endpoint on a port that was free a moment ago."""
    return f"tcp://127.0.0.1:{free_port()}"


def collect_raw(endpoint: str, seconds: float, stop: threading.Event | None = None) -> list[bytes]:
    """Pose payloads received on a raw SUB socket (no sasprobe code in the path)."""
    context = zmq.Context.instance()
    sock = context.socket(zmq.SUB)
    sock.linger = 0
    sock.rcvhwm = 100_000
    sock.setsockopt(zmq.SUBSCRIBE, b"pose")
    sock.connect(endpoint)
    payloads = []
    while not payloads:  # joining is asynchronous
        if sock.poll(5000) == 0:
            raise AssertionError("no pose within 5 s")
        payloads.append(sock.recv_multipart()[1])
    end = time.monotonic() + seconds
    while time.monotonic() < end and not (stop is not None and stop.is_set()):
        if sock.poll(50):
            while True:
                try:
                    payloads.append(sock.recv_multipart(zmq.NOBLOCK)[1])
                except zmq.Again:
                    break
    sock.close()
    return payloads
