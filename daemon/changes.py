"""The queue that hands changes to the loop: the control thread (daemon/requests.py)
prepares a change off the loop (parsing a structure, building an engine), then `submit`s
it as a closure and waits; the loop `apply`s every waiting closure at the start of its
next tick, on its own thread, with that tick's number. What a change replaced is handed
to `deferred_release` and freed by the submitting thread, never by the loop."""

from __future__ import annotations

import collections
from concurrent.futures import Future
from concurrent.futures import TimeoutError as FutureTimeout

from sasprobe.daemon.deferred_release import DeferredRelease

from sasprobe.common.errors import UserError

SUBMIT_TIMEOUT_S = 5.0


class ChangeQueue:
    def __init__(self) -> None:
        self._pending: collections.deque = collections.deque()  # (closure, Future)
        self.deferred_release = DeferredRelease()

    def submit(self, fn):
        """Run fn(seq) on the loop thread at the start of the next tick and return its result."""
        future: Future = Future()
        self._pending.append((fn, future))
        try:
            return future.result(timeout=SUBMIT_TIMEOUT_S)
        except FutureTimeout:
            raise UserError(
                "the daemon loop did not take the change in time (is it shutting down?)"
            ) from None
        finally:
            # what the change replaced, freed here rather than on the loop
            self.deferred_release.release()

    def __bool__(self) -> bool:
        """Whether changes wait (the loop's cheap test each tick)."""
        return bool(self._pending)

    def apply(self, seq: int) -> None:
        """On the loop thread: every waiting change, in order, at tick `seq`."""
        while self._pending:
            fn, future = self._pending.popleft()
            try:
                future.set_result(fn(seq))
            except Exception as exc:
                future.set_exception(exc)
