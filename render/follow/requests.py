"""Control requests from the renderer to the daemon (the view's turn, the clutch key,
recentre), sent on a thread of their own so a frame never waits for a reply.

Requests are sent in order; a newer `view` replaces one that has not gone out yet (only
the latest turn matters). A daemon that does not answer costs a warning, once, and the
request is dropped: the window keeps running and the next request tries again.
"""

from __future__ import annotations

import logging
import threading
from collections import deque

log = logging.getLogger("sasprobe")

REQUEST_TIMEOUT_S = 1.0
COALESCED = frozenset({"view"})  # only the newest one matters


class RequestSender:
    def __init__(self, ctl_endpoint: str, keys=None) -> None:
        self.endpoint = ctl_endpoint
        # Protocol.security.ClientKeys of a keyed daemon; None: as ControlClient defaults.
        self.keys = keys
        self._queue: deque[tuple[str, dict]] = deque()
        self._wake = threading.Condition()
        self._closed = False
        self._warned = False
        self.sent = 0
        self.failed = 0
        self._thread: threading.Thread | None = None

    def send(self, cmd: str, **args) -> None:
        """Queue a request (never blocks)."""
        with self._wake:
            if cmd in COALESCED:
                self._queue = deque(item for item in self._queue if item[0] != cmd)
            self._queue.append((cmd, args))
            if self._thread is None:
                self._thread = threading.Thread(
                    target=self._run, name="sasprobe-requests", daemon=True
                )
                self._thread.start()
            self._wake.notify()

    def _run(self) -> None:
        from sasprobe.protocol.client import ControlClient, ControlError

        client = ControlClient(self.endpoint, keys=self.keys, timeout_s=REQUEST_TIMEOUT_S)
        try:
            while True:
                with self._wake:
                    while not self._queue and not self._closed:
                        self._wake.wait()
                    if not self._queue:  # closed, and everything queued has gone out
                        return
                    cmd, args = self._queue.popleft()
                try:
                    client.call(cmd, **args)
                    self.sent += 1
                except ControlError as exc:
                    self.failed += 1
                    if not self._warned:
                        self._warned = True
                        log.warning("the daemon did not take '%s': %s", cmd, exc)
        finally:
            client.close()

    def close(self) -> None:
        """Send what is still queued (each with its timeout), then stop."""
        with self._wake:
            self._closed = True
            self._wake.notify()
        if self._thread is not None:
            self._thread.join(timeout=2.0 + REQUEST_TIMEOUT_S * len(self._queue))
