"""Child processes that never outlive their parent's intent.

Each child runs in its own session (so its own process group): a terminal's Ctrl+C
reaches only the parent, which stops the children in the order it chooses, and a
child's own children (ffmpeg under the renderer) are signalled and killed with it.
On Linux each child also gets PR_SET_PDEATHSIG, so it receives SIGTERM should the
parent die without cleaning up. Stopping is: a polite signal to the child, a bounded
wait, then SIGKILL to the whole group, which also sweeps up anything the child left.

`DaemonChild` is the one way this project starts `sasprobe daemon` as a child (the demo,
the daemon benchmark and the tests): it knows the daemon's ready and stopped events.
"""

from __future__ import annotations

import ctypes
import json
import os
import queue
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

from sasprobe.common.errors import UserError
from sasprobe.daemon import stdout_events

PR_SET_PDEATHSIG = 1
EXIT_WAIT_S = 10.0  # a child whose output ended gets this long to exit before it counts as silent

try:
    _LIBC = ctypes.CDLL(None, use_errno=True)  # this process's own symbols, libc's among them
except OSError:  # pragma: no cover
    _LIBC = None


def child_env(base: dict | None = None) -> dict:
    """The environment of a child: unbuffered, so events arrive as they happen; with the fault
    handler, so a crash in a driver leaves a trace in the log."""
    return dict(os.environ if base is None else base, PYTHONUNBUFFERED="1", PYTHONFAULTHANDLER="1")


def _child_setup(nice: int):
    """What runs in the child between fork and exec: die with the parent, lower priority."""

    def setup() -> None:
        if _LIBC is not None:
            try:
                _LIBC.prctl(PR_SET_PDEATHSIG, signal.SIGTERM)
            except AttributeError:  # no prctl (not Linux)
                pass
        if nice:
            os.nice(nice)

    return setup


def fatal_error(lines: list[str]) -> str:
    """`Fatal Python error: ...` and where the crashing thread was, from the lines of a
    fault-handler dump (PYTHONFAULTHANDLER); "" when there is none."""
    fatal = [k for k, line in enumerate(lines) if line.startswith("Fatal Python error:")]
    if not fatal:
        return ""
    start = fatal[-1]
    where = ""
    for k in range(start + 1, len(lines)):
        if lines[k].startswith("Current thread") and k + 1 < len(lines):
            frame = lines[k + 1]  # File "/a/b/c.py", line 9 in draw
            if frame.startswith('File "'):
                path, _, rest = frame.removeprefix('File "').partition('"')
                where = f" at {'/'.join(Path(path).parts[-2:])}{rest}"
            break
    return lines[start] + where


class Child:
    """A subprocess in its own process group whose stdout lines are JSON events
    (`{"event": ...}`) and whose stderr goes to a log file."""

    def __init__(
        self,
        name: str,
        argv: list[str],
        log_path: Path,
        env: dict | None = None,
        nice: int = 0,
        cwd: Path | None = None,
        registry: list | None = None,
    ) -> None:
        self.name = name
        self.argv = argv
        self.log_path = Path(log_path)
        self._log = open(self.log_path, "wb")
        self.proc = subprocess.Popen(
            argv,
            stdin=subprocess.DEVNULL,
            stdout=subprocess.PIPE,
            stderr=self._log,
            env=env,
            cwd=cwd,
            start_new_session=True,
            preexec_fn=_child_setup(nice),
        )
        if registry is not None:  # at once: a Ctrl+C from here on still finds the child to stop
            registry.append(self)
        self.pgid = self.proc.pid  # a session leader's group id is its pid
        self._events: queue.Queue = queue.Queue()
        self.events: dict[str, dict] = {}
        self._pump = threading.Thread(target=self._read_stdout, name=f"{name}-stdout", daemon=True)
        self._pump.start()

    def _read_stdout(self) -> None:
        for line in self.proc.stdout:
            try:
                event = json.loads(line)
            except ValueError:
                continue
            if isinstance(event, dict) and "event" in event:
                self.events[event["event"]] = event
                self._events.put(event)
        self._events.put(None)

    @property
    def pid(self) -> int:
        return self.proc.pid

    def alive(self) -> bool:
        return self.proc.poll() is None

    def wait_event(self, name: str, timeout_s: float) -> dict | None:
        """The first event called `name` (None if the child ends or time runs out first)."""
        if name in self.events:
            return self.events[name]
        deadline = time.monotonic() + timeout_s
        while True:
            remaining = deadline - time.monotonic()
            if remaining <= 0:
                return None
            try:
                event = self._events.get(timeout=min(remaining, 0.2))
            except queue.Empty:
                continue
            if event is None:
                self._events.put(None)  # keep the end marker for later callers
                return None
            if event["event"] == name:
                return event

    def error_line(self) -> str:
        """The child's own one-line error (`sasprobe: error: ...`); for a crash, the fault
        handler's fatal error and the innermost frame of the thread that crashed; else the
        log's last line."""
        try:
            text = self.log_path.read_text(errors="replace")
        except OSError:
            return ""
        lines = [line.strip() for line in text.splitlines() if line.strip()]
        crash = fatal_error(lines)
        if crash:
            return crash
        errors = [line for line in lines if line.startswith("sasprobe: error:")]
        line = errors[-1] if errors else (lines[-1] if lines else "")
        return line.removeprefix("sasprobe: error: ")

    def signal(self, sig: int) -> None:
        if self.alive():
            try:
                self.proc.send_signal(sig)
            except ProcessLookupError:
                pass

    def kill_group(self) -> None:
        """SIGKILL whatever is left in the child's process group (the child and its children)."""
        try:
            os.killpg(self.pgid, signal.SIGKILL)
        except (ProcessLookupError, PermissionError):
            pass

    def finish(self, timeout_s: float, hurry: threading.Event | None = None) -> int:
        """Wait for the child to exit (after it was signalled); SIGKILL its group when the
        time is up or `hurry` is set. Always sweeps the group and returns the exit status."""
        deadline = time.monotonic() + timeout_s
        while (
            self.alive()
            and time.monotonic() < deadline
            and not (hurry is not None and hurry.is_set())
        ):
            time.sleep(0.02)
        if self.alive():
            self.kill_group()
        rc = self.proc.wait()
        self.kill_group()  # e.g. an encoder the child started and did not reap
        self._pump.join(timeout=2.0)
        self._log.close()
        return rc


class DaemonChild(Child):
    """`python -m sasprobe daemon ARGS` in its own process group, stderr into `log_path`."""

    def __init__(
        self,
        args: list[str],
        log_path: Path,
        env: dict | None = None,
        nice: int = 0,
        cwd: Path | None = None,
        registry: list | None = None,
    ) -> None:
        super().__init__(
            "daemon",
            [sys.executable, "-m", "sasprobe", "daemon", *args],
            log_path,
            env=child_env(env),
            nice=nice,
            cwd=cwd,
            registry=registry,
        )

    def wait_ready(self, timeout_s: float) -> dict:
        """The daemon's ready event; UserError with its own error line when it ends first, or
        when it stays silent.

        Its stdout closes a moment before the process is gone: a daemon that failed is
        waited for (EXIT_WAIT_S at most), so its error line, not a timeout, is what is said."""
        deadline = time.monotonic() + timeout_s
        ready = self.wait_event(stdout_events.READY, timeout_s)
        if ready is not None:
            return ready
        if time.monotonic() < deadline:  # its output ended: it is exiting
            try:
                self.proc.wait(timeout=EXIT_WAIT_S)
            except subprocess.TimeoutExpired:
                pass
        if self.alive():
            raise UserError(f"the daemon did not start: no answer within {timeout_s:g} s")
        raise UserError(f"the daemon did not start: {self.error_line()}")

    @property
    def exit_report(self) -> dict | None:
        """The stopped event (the daemon's exit report), once it has printed it."""
        return self.events.get(stdout_events.STOPPED)

    def stop(
        self, timeout_s: float, sig: int = signal.SIGTERM, hurry: threading.Event | None = None
    ) -> int:
        """Signal the daemon (it writes zero force, closes the device and reports), wait, return
        its status."""
        self.signal(sig)
        return self.finish(timeout_s, hurry)
