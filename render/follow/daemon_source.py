"""A running daemon as the renderer's source (`sasprobe render --connect`).

The structure comes from the daemon's control endpoint as arrays (`get_structure` form
"arrays": the daemon's parsed atoms, which unpack far faster than the file parses, so a
large structure is drawn soon after joining), fetched on a thread so a window stays
responsive. Poses and scenes come from its publisher, drained once per frame without
blocking. Nothing for STALE_S and the daemon counts as gone ('waiting for daemon'); ZeroMQ
reconnects by itself, and a daemon serving another structure (its scene's sha256 changed)
is followed.

The haptic rate is poses over RATE_WINDOW_S of the daemon's device time, in a window of at
most RATE_WINDOW_POSES poses that starts again when the device clock or the sequence number
goes back (a restarted daemon).
"""

from __future__ import annotations

import logging
import threading
import time
from collections import deque

import numpy as np
from sasprobe.molecule import DEFAULT_PROBE_RADIUS, Structure, parse_structure
from sasprobe.molecule.packed import unpack_structure
from sasprobe.protocol.client import ControlClient, ControlError, Subscriber, fetch_structure
from sasprobe.protocol.endpoints import DEFAULT_CTL_ENDPOINT, DEFAULT_PUB_ENDPOINT
from sasprobe.protocol.pose import FLAG_CLUTCHED, FLAG_DRIFTING
from sasprobe.protocol.security import ClientKeys
from sasprobe.protocol.view import view_axes
from sasprobe.render.follow.live_clearance import LiveClearance
from sasprobe.render.follow.messages import (
    apply_pose,
    apply_scene_message,
    touched_label,
)
from sasprobe.render.follow.requests import RequestSender
from sasprobe.render.scene_state import NavCube, Probe
from sasprobe.render.source import Readout, RenderSource

from sasprobe.common.errors import UserError

log = logging.getLogger("sasprobe")

STALE_S = 1.5  # the daemon sends a scene at least once a second and poses at ~1 kHz
RETRY_S = 1.0  # between structure fetch attempts
FETCH_TIMEOUT_S = 2.0
RATE_WINDOW_S = 0.5  # haptic rate: poses over this much device time ...
RATE_WINDOW_POSES = 4096  # ... and never more poses than this
NOTE_S = 3.0  # how long the answer to a dropped mark stays in the readout


class DaemonSource(RenderSource):
    """A running daemon as the renderer's source (see the module's docstring)."""

    follows_daemon = True

    def __init__(
        self,
        pub: str | None = None,
        ctl: str | None = None,
        keep_water: bool = False,
        keys: ClientKeys | None = None,
    ):
        self.pub = pub or DEFAULT_PUB_ENDPOINT
        self.ctl = ctl or DEFAULT_CTL_ENDPOINT
        self.keep_water = keep_water
        self.keys = keys  # None: the local keys for loopback TCP, none for ipc (protocol/client.py)
        self.subscriber = Subscriber(self.pub, keys=keys)
        self.requests = RequestSender(self.ctl, keys)
        self.structure: Structure | None = None  # the one handed out last
        self._fetched: Structure | None = None
        self._fetch_error: str | None = None
        self._thread: threading.Thread | None = None
        self._last_attempt = -np.inf
        self._last_data = -np.inf
        self._ever_connected = False
        self._seen = 0
        self._recent: deque[tuple[int, int]] = deque(maxlen=RATE_WINDOW_POSES)  # (device_t_ns, seq)
        self._daemon_probe_light: bool | None = None
        self._daemon_scheme: str | None = None
        self.live = LiveClearance()
        self._live_wanted = False
        self._note = ("", 0.0)  # (text, until when)

    # ------------------------------------------------------------ structure
    def _fetch(self) -> None:
        try:
            # --keep-water: the file, parsed with the waters (the daemon may have removed them);
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
            if served.form == "arrays":
                self._fetched = unpack_structure(
                    served.data, served.name, served.source, served.sha256
                )
            else:
                self._fetched = parse_structure(
                    served.data,
                    name=served.name,
                    source=served.source,
                    keep_water=self.keep_water or served.keep_water,
                )
            self._fetch_error = None
        except UserError as exc:  # ControlError, or a StructureError from the bytes
            self._fetch_error = str(exc)

    def _want_structure(self) -> bool:
        if self._fetched is not None or (self._thread is not None and self._thread.is_alive()):
            return False
        if self.structure is None:
            return True
        scene = self.subscriber.scene
        return scene is not None and scene["structure"]["sha256"] != self.structure.sha256

    def take_new_structure(self) -> Structure | None:
        structure, self._fetched = self._fetched, None
        if structure is not None:
            self.structure = structure
            log.info("daemon structure: %s (%d atoms)", structure.name, structure.n_atoms)
        return structure

    # ------------------------------------------------------------ stream
    def poll(self) -> None:
        poses = self.subscriber.poll()
        seen = self.subscriber.poses_received + self.subscriber.scenes_received
        now = time.monotonic()
        if seen != self._seen:
            self._seen, self._last_data = seen, now
            self._ever_connected = True
        scene = self.subscriber.scene
        if (
            self._live_wanted
            and self.structure is not None
            and scene is not None
            and scene["structure"]["sha256"] == self.structure.sha256
        ):
            self.live.update(self.structure, float(scene["probe_radius_A"]), poses)
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

    @property
    def connected(self) -> bool:
        return time.monotonic() - self._last_data < STALE_S

    def lost_for_s(self) -> float:
        """Seconds since a daemon that was sending stopped (0 while it sends, or before it ever
        did)."""
        return (
            0.0
            if not self._ever_connected or self.connected
            else time.monotonic() - self._last_data
        )

    def apply(self, scene) -> None:
        """The daemon's probe, cube, planes and lights into the renderer's SceneState."""
        state, pose = self.subscriber.scene, self.subscriber.pose
        if state is not None:
            probe_light = apply_scene_message(scene, state)
            # Follow the daemon's changes; keys still toggle
            if probe_light != self._daemon_probe_light:
                scene.effects.probe_light = self._daemon_probe_light = probe_light
            # Null: every renderer keeps its own (--color, or its default)
            scheme = state.get("color_scheme")
            if scheme is not None and scheme != self._daemon_scheme:
                scene.effects.color_scheme = self._daemon_scheme = scheme
        if pose is not None:
            apply_pose(
                scene,
                pose,
                cube_enabled=state is None or state["nav_cube"]["enabled"],
                axes=view_axes(state),
            )

    def view_axes(self) -> np.ndarray:
        return view_axes(self.subscriber.scene)

    def preview(self):
        """The cube and the probe of the newest pose, while the structure is on its way."""
        state, pose = self.subscriber.scene, self.subscriber.pose
        if (
            pose is None
            or not self.connected
            or (state is not None and not state["nav_cube"]["enabled"])
            or not (pose.cube_half_A > 0 and np.all(np.isfinite(pose.cube_center_A)))
        ):
            return None, None
        radius = float(state["probe_radius_A"]) if state is not None else DEFAULT_PROBE_RADIUS
        cube = NavCube(
            center=np.array(pose.cube_center_A, dtype=np.float64),
            half=float(pose.cube_half_A),
            axes=view_axes(state),
        )
        return cube, Probe(center=np.array(pose.proxy_A, dtype=np.float64), radius=radius)

    def request(self, cmd: str, **args) -> bool:
        self.requests.send(cmd, **args)
        return True

    def readout(self) -> Readout:
        pose = self.subscriber.pose
        connected = self.connected
        status = ""
        if not connected:
            status = f"waiting for daemon at {self.pub}"
            if self._fetch_error and self.structure is None:
                status += f" ({self._fetch_error})"
        elif self.structure is None:  # it is running (poses arrive): its structure is on the way
            status = f"fetching the structure from {self.ctl}"
        rate = None
        if len(self._recent) >= 2 and self._recent[-1][0] > self._recent[0][0]:
            (t0, s0), (t1, s1) = self._recent[0], self._recent[-1]
            rate = (s1 - s0) / ((t1 - t0) * 1e-9)
        live = connected and pose is not None
        limits = ((self.subscriber.scene or {}).get("device") or {}).get("limits") or {}
        clearance = self.live if connected else LiveClearance()
        note, until = self._note
        return Readout(
            status=status,
            haptic_hz=rate if connected else None,
            force_n=float(np.linalg.norm(pose.force_N)) if live else None,
            dropped=self.subscriber.malformed,
            touched=touched_label(self.structure, pose.touched_atom) if live else None,
            continuous_force_n=limits.get("continuous_force_n"),
            peak_force_n=limits.get("max_force_n"),
            clutched=live and pose.has(FLAG_CLUTCHED),
            drifting=live and pose.has(FLAG_DRIFTING),
            clearance_A=clearance.clearance_A,
            passage_A=clearance.passage_A,
            bottleneck_A=clearance.bottleneck_A,
            note=note if time.monotonic() < until else "",
        )

    def show_live_clearance(self) -> None:
        self._live_wanted = True

    def drop_mark(self) -> None:
        """Ask the daemon for a mark (control `mark`) on a thread, so the window never waits."""

        def ask() -> None:
            try:
                with ControlClient(self.ctl, keys=self.keys, timeout_s=FETCH_TIMEOUT_S) as client:
                    mark = client.mark()["mark"]
                text = f"mark {mark['id']} dropped"
            except UserError as exc:
                text = f"no mark: {exc}"
            self._note = (text, time.monotonic() + NOTE_S)

        threading.Thread(target=ask, name="sasprobe-mark", daemon=True).start()

    def wait_ready(self, timeout_s: float = 10.0) -> None:
        """Block until the structure and a first pose are in (headless start), or one clear line."""
        deadline = time.monotonic() + timeout_s
        while self._fetched is None or self.subscriber.pose is None:
            if time.monotonic() > deadline:
                why = (
                    self._fetch_error or f"no pose on {self.pub}: {self.subscriber.watch.explain()}"
                )
                raise UserError(f"no daemon answered within {timeout_s:g} s: {why}")
            self.poll()
            time.sleep(0.02)

    def stream_report(self) -> dict:
        sub = self.subscriber
        return {
            "poses_received": sub.poses_received,
            "poses_missed": sub.missed,
            "scenes_received": sub.scenes_received,
            "malformed": sub.malformed,
        }

    def close(self) -> None:
        self.requests.close()
        self.subscriber.close()
