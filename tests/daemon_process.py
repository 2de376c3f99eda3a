"""Run `sasprobe daemon` as a real subprocess on ipc:// sockets in a private folder."""

from __future__ import annotations

import json
import os
import queue
import shutil
import signal
import subprocess
import sys
import tempfile
import threading
from pathlib import Path

REPO_ROOT = Path(__file__).resolve().parent.parent
CLI = [sys.executable, "-m", "sasprobe"]
DEVICE = "sim"


def cli(*args: str, timeout: float = 120, **kwargs) -> subprocess.CompletedProcess:
    """Run `sasprobe ARGS` as a user would."""
    return subprocess.run([*CLI, *args], capture_output=True, text=True, timeout=timeout, cwd=REPO_ROOT,
                          env=dict(os.environ, PYTHONUNBUFFERED="1"), **kwargs)


def cli_many(*commands: tuple[str, ...], timeout: float = 120) -> list[subprocess.CompletedProcess]:
    """Run several `sasprobe` commands at once (start-up dominates short ones)."""
    procs = [subprocess.Popen([*CLI, *args], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                              cwd=REPO_ROOT, env=dict(os.environ, PYTHONUNBUFFERED="1")) for args in commands]
    results = []
    for args, proc in zip(commands, procs):
        out, err = proc.communicate(timeout=timeout)
        results.append(subprocess.CompletedProcess([*CLI, *args], proc.returncode, out, err))
    return results


class DaemonProcess:
    def __init__(self, *args: str, device: str = DEVICE, pub: str | None = None, ctl: str | None = None,
                 ready_timeout: float = 90.0) -> None:
        self.sockets = Path(tempfile.mkdtemp(prefix="spd"))  # short: ipc paths are limited to ~100 bytes
        self.pub = pub or f"ipc://{self.sockets}/pub"
        self.ctl = ctl or f"ipc://{self.sockets}/ctl"
        command = [*CLI, "daemon", "--device", device, "--pub", self.pub, "--ctl", self.ctl, *args]
        # cwd: the private folder, so nothing a test asks the daemon to write lands in the checkout
        self.proc = subprocess.Popen(command, cwd=self.sockets, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                                     text=True, env=dict(os.environ, PYTHONUNBUFFERED="1"))
        self._lines: queue.Queue = queue.Queue()
        self.stderr_lines: list[str] = []
        threading.Thread(target=self._pump, args=(self.proc.stdout, self._lines.put), daemon=True).start()
        threading.Thread(target=self._pump, args=(self.proc.stderr, self.stderr_lines.append), daemon=True).start()
        self.ready = self._next_event("ready", ready_timeout)

    @staticmethod
    def _pump(stream, sink) -> None:
        for line in stream:
            sink(line)
        sink(None)  # end of stream

    def _next_event(self, name: str, timeout: float) -> dict:
        while True:
            try:
                line = self._lines.get(timeout=timeout)
            except queue.Empty:
                raise AssertionError(f"daemon printed no '{name}' within {timeout} s; stderr: {self.stderr}") from None
            if line is None:
                raise AssertionError(f"daemon exited ({self.proc.wait()}) before '{name}'; stderr: {self.stderr}")
            try:
                event = json.loads(line)
            except ValueError:
                continue
            if event.get("event") == name:
                return event

    @property
    def stderr(self) -> str:
        return "".join(line for line in self.stderr_lines if line)

    def stop(self, sig: int = signal.SIGTERM, timeout: float = 30.0) -> tuple[int, dict | None]:
        """Signal the daemon, wait for it, return (exit status, exit report or None)."""
        if self.proc.poll() is None:
            self.proc.send_signal(sig)
        rc = self.proc.wait(timeout=timeout)
        report = None
        if sig != signal.SIGKILL:
            try:
                report = self._next_event("stopped", 5.0)
            except AssertionError:
                report = None
        shutil.rmtree(self.sockets, ignore_errors=True)
        return rc, report

    def __enter__(self) -> DaemonProcess:
        return self

    def __exit__(self, *exc) -> None:
        if self.proc.poll() is None:
            self.proc.kill()
            self.proc.wait()
        shutil.rmtree(self.sockets, ignore_errors=True)
