"""The control command `findings`: the analysis of a running daemon's recording so far.

It is the analysis `sasprobe replay FILE --findings DIR` runs (daemon/findings/), on the
file the daemon is writing, read up to its last flushed chunk. It runs in a child
process (`python -m sasprobe.daemon.findings`) so the loop never waits for a GIL held by
the analysis (matplotlib and gemmi hold it for long stretches), and the child starts
with normal scheduling, never with the daemon's SCHED_FIFO: the control thread drops to
normal scheduling just for the fork and takes its priority back after it. The child's
progress goes to the daemon's stderr, its one-line JSON result to a pipe read by a
watcher thread; `status` reports the job. A child still running when the daemon stops
finishes its files on its own.
"""

from __future__ import annotations

import json
import logging
import os
import subprocess
import sys
import threading
import time
from pathlib import Path

log = logging.getLogger("sasprobe")


class FindingsJob:
    def __init__(self, recording: Path, out_dir: str, probe_radius_A: float | None = None) -> None:
        self.recording = Path(recording)
        self.out_dir = str(out_dir)
        self.state = "running"
        self.error: str | None = None
        self.result: dict | None = None
        self.started_unix_s = time.time()
        argv = [
            sys.executable,
            "-m",
            "sasprobe.daemon.findings",
            str(self.recording),
            self.out_dir,
            "--json",
        ]
        if probe_radius_A is not None:
            argv += ["--probe-radius", repr(float(probe_radius_A))]
        with _normal_scheduling():
            self._proc = subprocess.Popen(
                argv,
                stdin=subprocess.DEVNULL,
                stdout=subprocess.PIPE,
                text=True,
                start_new_session=True,  # a terminal's Ctrl+C stops the daemon, not its analysis
            )
        self._thread = threading.Thread(target=self._watch, name="sasprobe-findings", daemon=True)
        self._thread.start()
        log.warning(
            "findings: analysing %s into %s (pid %d)", self.recording, self.out_dir, self._proc.pid
        )

    @property
    def running(self) -> bool:
        return self.state == "running"

    def _watch(self) -> None:
        out = self._proc.stdout.read()
        rc = self._proc.wait()
        lines = out.strip().splitlines()
        try:
            reply = json.loads(lines[-1]) if lines else {}
        except ValueError:
            reply = {}
        if rc == 0 and "error" not in reply:
            self.result, self.state = reply, "done"
        else:
            self.error = reply.get("error") or f"the analysis ended with status {rc}"
            self.state = "failed"
        log.warning(
            "findings into %s: %s", self.out_dir, self.state if self.error is None else self.error
        )

    def as_dict(self) -> dict:
        return {
            "dir": self.out_dir,
            "recording": str(self.recording),
            "state": self.state,
            "pid": self._proc.pid,
            "started_unix_s": self.started_unix_s,
            "error": self.error,
            "result": self.result,
        }


class _normal_scheduling:
    """The calling thread at normal scheduling for a moment (what a child forked now inherits)."""

    def __enter__(self):
        self._saved = None
        try:
            policy = os.sched_getscheduler(0)
            if policy != os.SCHED_OTHER:
                self._saved = (policy, os.sched_getparam(0))
                os.sched_setscheduler(0, os.SCHED_OTHER, os.sched_param(0))
        except (OSError, AttributeError):
            self._saved = None
        return self

    def __exit__(self, *exc) -> None:
        if self._saved is not None:
            try:
                os.sched_setscheduler(0, self._saved[0], self._saved[1])
            except OSError as err:
                log.warning("findings: could not restore the control thread's priority: %s", err)
