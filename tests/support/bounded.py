"""Waits in tests that end: a thread joined, or a child's output read, within a time limit,
failing with what was waited for (the per-test limit of pytest-timeout is the last resort)."""

from __future__ import annotations

import queue
import sys
import threading
import time
import traceback


def join(thread: threading.Thread, timeout_s: float = 30.0) -> None:
    """Join `thread`; AssertionError with its stack when it still runs after `timeout_s`."""
    thread.join(timeout_s)
    if thread.is_alive():
        frame = sys._current_frames().get(thread.ident)
        stack = "".join(traceback.format_stack(frame)) if frame is not None else "(no stack)\n"
        raise AssertionError(
            f"the thread {thread.name!r} still runs after {timeout_s:g} s:\n{stack}"
        )


def lines_until(stream, done, timeout_s: float) -> list[str]:
    """The lines of a text stream (a child's pipe) up to the first for which `done(line)` holds,
    or up to its end, or those that came within `timeout_s`: read on a thread, so the wait ends
    even when the child writes nothing more. The thread stops at that line."""
    lines: queue.Queue = queue.Queue()

    def pump() -> None:
        for line in stream:
            lines.put(line)
            if done(line):
                break
        lines.put(None)

    threading.Thread(target=pump, name="lines_until", daemon=True).start()
    seen: list[str] = []
    deadline = time.monotonic() + timeout_s
    while True:
        try:
            line = lines.get(timeout=max(deadline - time.monotonic(), 0.0))
        except queue.Empty:
            return seen
        if line is None:
            return seen
        seen.append(line)
        if done(line):
            return seen
