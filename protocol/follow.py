"""Following a running daemon, as `sasprobe render --connect` and `sasprobe web` both do.

The pose and scene come from the daemon's publisher through the Subscriber, drained without
blocking by `poll()`. The structure comes from the control endpoint (`get_structure`, form
"arrays": the daemon's parsed atoms as flat arrays, which unpack far faster than the file
parses, so a remote follower needs no shared disk), fetched on a background thread so the
caller never waits; a daemon serving another structure (its scene's sha256 changed) makes it
fetch that one. The protocol knows nothing of structures: `decode` turns what the daemon
served into the caller's structure (molecule/packed.py `structure_from_served`), which must
carry the file's `sha256`.

When nothing arrives for STALE_S the daemon counts as gone; ZeroMQ reconnects by itself
when it returns (or starts after the follower), and a restarted daemon's structure is
fetched again when its sha256 differs. The haptic rate is poses over RATE_WINDOW_S of the
daemon's device time, in a window of at most RATE_WINDOW_POSES poses that starts again
whenever the device clock or the sequence number goes back (a restarted daemon starts both
again).
"""

from __future__ import annotations

import threading
import time
from collections import deque
from collections.abc import Callable

import numpy as np
from sasprobe.protocol.client import ControlError, StructureFile, Subscriber, fetch_structure
from sasprobe.protocol.endpoints import DEFAULT_CTL_ENDPOINT, DEFAULT_PUB_ENDPOINT
from sasprobe.protocol.pose import Pose
from sasprobe.protocol.security import ClientKeys

from sasprobe.common.errors import UserError

STALE_S = 1.5  # the daemon sends a scene at least once a second and poses at ~1 kHz
RETRY_S = 1.0  # between structure fetch attempts
FETCH_TIMEOUT_S = 2.0
RATE_WINDOW_S = 0.5  # haptic rate: poses over this much device time ...
RATE_WINDOW_POSES = 4096  # ... and never more poses than this


class DaemonFollow:
    """A daemon's newest pose and scene, its structure, whether it is there, and its rate."""

    def __init__(
        self,
        decode: Callable[[StructureFile], object],
        pub: str | None = None,
        ctl: str | None = None,
        keys: ClientKeys | None = None,
        keep_water: bool = False,
    ) -> None:
        self.pub = pub or DEFAULT_PUB_ENDPOINT
        self.ctl = ctl or DEFAULT_CTL_ENDPOINT
        self.keys = keys  # None: the local keys for loopback TCP, none for ipc (protocol/client.py)
        self.keep_water = keep_water  # the file parsed with its waters, not the daemon's arrays
        self.decode = decode
        self.subscriber = Subscriber(self.pub, keys=keys)
        self.structure = None  # the one handed out last
        self.fetch_error: str | None = None
        self._fetched = None
        self._thread: threading.Thread | None = None
        self._last_attempt = -np.inf
        self._last_data = -np.inf
        self._ever_connected = False
        self._seen = 0
        self._data_in_last_poll = False
        self._recent: deque[tuple[int, int]] = deque(maxlen=RATE_WINDOW_POSES)  # (device_t_ns, seq)

    # ------------------------------------------------------------ structure
    def _fetch(self) -> None:
        try:
            # keep_water: the file, parsed with the waters (the daemon may have removed them);
            # a daemon that serves no arrays (an older version) refuses the form: the file then
            served = None
            if not self.keep_water:
                try:
                    served = fetch_structure(
                        self.ctl, keys=self.keys, timeout_s=FETCH_TIMEOUT_S, form="arrays"
                    )
                except ControlError as exc:
                    if "get_structure" not in str(exc):
                        raise
            if served is None:
                served = fetch_structure(self.ctl, keys=self.keys, timeout_s=FETCH_TIMEOUT_S)
            self._fetched = self.decode(served)
            self.fetch_error = None
        except UserError as exc:  # ControlError, or the bytes did not decode
            self.fetch_error = str(exc)

    def _want_structure(self) -> bool:
        if self._fetched is not None or (self._thread is not None and self._thread.is_alive()):
            return False
        if self.structure is None:
            return True
        scene = self.subscriber.scene
        return scene is not None and scene["structure"]["sha256"] != self.structure.sha256

    def take_new_structure(self):
        """The structure fetched since the last call (once), else None."""
        structure, self._fetched = self._fetched, None
        if structure is not None:
            self.structure = structure
        return structure

    def current_structure(self) -> bool:
        """Whether the structure handed out is the one the daemon's scene names."""
        scene = self.subscriber.scene
        return (
            self.structure is not None
            and scene is not None
            and scene["structure"]["sha256"] == self.structure.sha256
        )

    # ------------------------------------------------------------ stream
    def poll(self, timeout_s: float = 0.0) -> list[Pose]:
        """Take in what has arrived (waiting up to timeout_s for it); the poses, oldest first.
        The time since a poll that brought something was the caller's own (a frame, the
        clearance: seconds for a renderer short of CPU), not the daemon's silence: that is
        counted from the first poll that brings nothing."""
        if self._data_in_last_poll:
            self._last_data = time.monotonic()
        poses = self.subscriber.poll(timeout_s)
        seen = self.subscriber.poses_received + self.subscriber.scenes_received
        now = time.monotonic()
        self._data_in_last_poll = seen != self._seen
        if self._data_in_last_poll:
            self._seen, self._last_data = seen, now
            self._ever_connected = True
        recent = self._recent
        for pose in poses:
            if recent and (pose.device_t_ns < recent[-1][0] or pose.seq < recent[-1][1]):
                recent.clear()  # a restarted daemon: its clock and its ticks start again
            recent.append((pose.device_t_ns, pose.seq))
        while len(recent) > 2 and recent[-1][0] - recent[0][0] > RATE_WINDOW_S * 1e9:
            recent.popleft()
        if self._want_structure() and now - self._last_attempt >= RETRY_S:
            self._last_attempt = now
            self._thread = threading.Thread(
                target=self._fetch, name="sasprobe-fetch-structure", daemon=True
            )
            self._thread.start()
        return poses

    @property
    def connected(self) -> bool:
        return time.monotonic() - self._last_data < STALE_S

    def lost_for_s(self) -> float:
        """Seconds since a daemon that was sending stopped (0 while it sends or before it did)."""
        if not self._ever_connected or self.connected:
            return 0.0
        return time.monotonic() - self._last_data

    def haptic_rate_hz(self) -> float | None:
        """Poses a second of device time over the rate window; None before two poses."""
        if len(self._recent) >= 2 and self._recent[-1][0] > self._recent[0][0]:
            (t0, s0), (t1, s1) = self._recent[0], self._recent[-1]
            return (s1 - s0) / ((t1 - t0) * 1e-9)
        return None

    def wait_ready(self, timeout_s: float = 10.0) -> None:
        """Block until the structure and a first pose are in, or one clear line (UserError)."""
        deadline = time.monotonic() + timeout_s
        while self._fetched is None or self.subscriber.pose is None:
            if time.monotonic() > deadline:
                why = (
                    self.fetch_error or f"no pose on {self.pub}: {self.subscriber.watch.explain()}"
                )
                raise UserError(f"no daemon answered within {timeout_s:g} s: {why}")
            self.poll()
            time.sleep(0.02)

    def close(self) -> None:
        self.subscriber.close()
