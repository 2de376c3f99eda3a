"""Waits in tests that end: a thread joined within a time limit, failing with the stack of
the thread that did not end (the per-test limit of pytest-timeout is the last resort)."""

from __future__ import annotations

import sys
import threading
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
