"""Following a running daemon (`sasprobe render --connect`).

The structure comes from the daemon's control endpoint (`get_structure`: the file bytes,
so a remote renderer needs no shared disk), fetched on a background thread so a window
stays responsive; the pose and scene come from its publisher through the protocol's
Subscriber, drained once per frame without blocking. When nothing arrives for
STALE_S the daemon counts as gone and the readout says 'waiting for daemon'; ZeroMQ
reconnects by itself when it returns, and a daemon serving another structure (its
scene's sha256 changed) makes the link fetch that one. Malformed messages are dropped
and counted by the Subscriber.
"""

from __future__ import annotations

import logging
import threading
import time
from collections import deque

import numpy as np

from sasprobe.errors import UserError
from sasprobe.molecule import Structure, parse_structure
from sasprobe.protocol.client import ControlClient, Subscriber, fetch_structure
from sasprobe.protocol.endpoints import DEFAULT_CTL_ENDPOINT, DEFAULT_PUB_ENDPOINT
from sasprobe.render.live_clearance import LiveClearance
from sasprobe.render.scene import Mark, NavCube, Probe, normalise_plane
from sasprobe.render.source import Readout, RenderSource

log = logging.getLogger("sasprobe")

STALE_S = 1.5  # the daemon sends a scene at least once a second and poses at ~1 kHz
RETRY_S = 1.0  # between structure fetch attempts
FETCH_TIMEOUT_S = 2.0
RATE_WINDOW_S = 0.5  # haptic rate: poses over this much device time
NOTE_S = 3.0  # how long the answer to a dropped mark stays in the readout


def apply_scene_message(scene, state: dict) -> bool:
    """A `scene` message's probe radius, clip planes, light direction and marks into a SceneState
    (its grid then follows the daemon's probe radius); returns whether the daemon has the
    probe light on (the caller decides whether to follow)."""
    scene.probe_radius = float(state["probe_radius_A"])
    planes = [normalise_plane(p) for p in state["clip_planes"]]
    if len(planes) != len(scene.clip_planes) or any(not np.array_equal(a, b) for a, b in zip(planes, scene.clip_planes)):
        scene.clip_planes = planes
    lights = state["lights"]
    direction = np.asarray(lights["directional"]["direction"], dtype=np.float64)
    scene.light_direction = direction / np.linalg.norm(direction)
    marks = [Mark(int(m["id"]), m["label"], tuple(map(float, m["position_A"]))) for m in state.get("marks", [])]
    if marks != scene.marks:
        scene.marks = marks
    return bool(lights["probe"]["enabled"])


def apply_pose(scene, pose, cube_enabled: bool) -> None:
    """A pose's probe, touched atom and navigation cube into a SceneState."""
    touched = pose.touched_atom if 0 <= pose.touched_atom < scene.structure.n_atoms else -1
    scene.probe = Probe(center=np.array(pose.proxy_A, dtype=np.float64), radius=scene.probe_radius,
                        touched_atom=touched)
    if cube_enabled and pose.cube_half_A > 0 and np.all(np.isfinite(pose.cube_center_A)):
        center = np.array(pose.cube_center_A, dtype=np.float64)
        if scene.nav_cube is None or not np.array_equal(scene.nav_cube.center, center) \
                or scene.nav_cube.half != pose.cube_half_A:
            scene.nav_cube = NavCube(center=center, half=float(pose.cube_half_A))
    else:
        scene.nav_cube = None


class DaemonLink(RenderSource):
    def __init__(self, pub: str | None = None, ctl: str | None = None, keep_water: bool = False):
        self.pub = pub or DEFAULT_PUB_ENDPOINT
        self.ctl = ctl or DEFAULT_CTL_ENDPOINT
        self.keep_water = keep_water
        self.subscriber = Subscriber(self.pub)
        self.structure: Structure | None = None  # the one handed out last
        self._fetched: Structure | None = None
        self._fetch_error: str | None = None
        self._thread: threading.Thread | None = None
        self._last_attempt = -np.inf
        self._last_data = -np.inf
        self._seen = 0
        self._recent: deque[tuple[int, int]] = deque()  # (device_t_ns, seq) of recent poses
        self._daemon_probe_light: bool | None = None
        self.live = LiveClearance()
        self._live_wanted = False
        self._note = ("", 0.0)  # (text, until when)

    # ------------------------------------------------------------ structure
    def _fetch(self) -> None:
        try:
            served = fetch_structure(self.ctl, timeout_s=FETCH_TIMEOUT_S)
            self._fetched = parse_structure(served.data, name=served.name, source=served.source,
                                            keep_water=self.keep_water or served.keep_water)
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
        scene = self.subscriber.scene
        if self._live_wanted and self.structure is not None and scene is not None \
                and scene["structure"]["sha256"] == self.structure.sha256:
            self.live.update(self.structure, float(scene["probe_radius_A"]), poses)
        for pose in poses:
            self._recent.append((pose.device_t_ns, pose.seq))
        while len(self._recent) > 2 and self._recent[-1][0] - self._recent[0][0] > RATE_WINDOW_S * 1e9:
            self._recent.popleft()
        if self._want_structure() and now - self._last_attempt >= RETRY_S:
            self._last_attempt = now
            self._thread = threading.Thread(target=self._fetch, name="sasprobe-fetch-structure", daemon=True)
            self._thread.start()

    @property
    def connected(self) -> bool:
        return time.monotonic() - self._last_data < STALE_S

    def apply(self, scene) -> None:
        """The daemon's probe, cube, planes and lights into the renderer's SceneState."""
        state, pose = self.subscriber.scene, self.subscriber.pose
        if state is not None:
            probe_light = apply_scene_message(scene, state)
            if probe_light != self._daemon_probe_light:  # follow the daemon's changes; keys still toggle
                scene.effects.probe_light = self._daemon_probe_light = probe_light
        if pose is not None:
            apply_pose(scene, pose, cube_enabled=state is None or state["nav_cube"]["enabled"])

    def readout(self) -> Readout:
        pose = self.subscriber.pose
        status = ""
        if not self.connected or self.structure is None:
            status = f"waiting for daemon at {self.pub}"
            if self._fetch_error and self.structure is None:
                status += f" ({self._fetch_error})"
        rate = None
        if len(self._recent) >= 2 and self._recent[-1][0] > self._recent[0][0]:
            (t0, s0), (t1, s1) = self._recent[0], self._recent[-1]
            rate = (s1 - s0) / ((t1 - t0) * 1e-9)
        force = float(np.linalg.norm(pose.force_N)) if pose is not None else None
        live = self.live if self.connected else LiveClearance()
        note, until = self._note
        return Readout(status=status, haptic_hz=rate if self.connected else None,
                       force_n=force if self.connected else None, dropped=self.subscriber.malformed,
                       clearance_A=live.clearance_A, passage_A=live.passage_A, bottleneck_A=live.bottleneck_A,
                       note=note if time.monotonic() < until else "")

    def show_live_clearance(self) -> None:
        self._live_wanted = True

    def drop_mark(self) -> None:
        """Ask the daemon for a mark (control `mark`) on a thread, so the window never waits."""
        def ask() -> None:
            try:
                with ControlClient(self.ctl, timeout_s=FETCH_TIMEOUT_S) as client:
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
                why = self._fetch_error or f"no pose on {self.pub}"
                raise UserError(f"no daemon answered within {timeout_s:g} s: {why} (start one with `sasprobe daemon`)")
            self.poll()
            time.sleep(0.02)

    def stream_report(self) -> dict:
        sub = self.subscriber
        return {"poses_received": sub.poses_received, "poses_missed": sub.missed,
                "scenes_received": sub.scenes_received, "malformed": sub.malformed}

    def close(self) -> None:
        self.subscriber.close()
