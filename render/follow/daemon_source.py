"""A running daemon as the renderer's source (`sasprobe render --connect`).

The pose, the scene and the structure come through protocol/follow.py (what `sasprobe web`
follows the daemon with too): poses and scenes drained once per frame without blocking,
the structure fetched on a thread so a window stays responsive. While the daemon is gone
the readout says 'waiting for daemon'. What only the window needs stays here: the readout,
the requests it makes (follow/requests.py), marks and the live clearance.
"""

from __future__ import annotations

import logging
import threading
import time

import numpy as np
from sasprobe.molecule import DEFAULT_PROBE_RADIUS, Structure
from sasprobe.molecule.packed import structure_from_served
from sasprobe.molecule.residues import touched_label
from sasprobe.protocol.client import ControlClient
from sasprobe.protocol.follow import FETCH_TIMEOUT_S, DaemonFollow
from sasprobe.protocol.pose import FLAG_CLUTCHED, FLAG_DRIFTING
from sasprobe.protocol.security import ClientKeys
from sasprobe.protocol.view import view_axes
from sasprobe.render.follow.live_clearance import LiveClearance
from sasprobe.render.follow.messages import apply_pose, apply_scene_message
from sasprobe.render.follow.requests import RequestSender
from sasprobe.render.scene_state import NavCube, Probe
from sasprobe.render.source import Readout, RenderSource

from sasprobe.common.errors import UserError

log = logging.getLogger("sasprobe")

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
        self.follow = DaemonFollow(
            lambda served: structure_from_served(served, keep_water), pub, ctl, keys, keep_water
        )
        self.pub, self.ctl, self.keys = self.follow.pub, self.follow.ctl, keys
        self.subscriber = self.follow.subscriber
        self.requests = RequestSender(self.ctl, keys)
        self._daemon_probe_light: bool | None = None
        self._daemon_scheme: str | None = None
        self.live = LiveClearance()
        self._live_wanted = False
        self._note = ("", 0.0)  # (text, until when)

    @property
    def structure(self) -> Structure | None:
        """The structure handed out last."""
        return self.follow.structure

    @structure.setter
    def structure(self, structure: Structure | None) -> None:
        self.follow.structure = structure

    def take_new_structure(self) -> Structure | None:
        structure = self.follow.take_new_structure()
        if structure is not None:
            log.info("daemon structure: %s (%d atoms)", structure.name, structure.n_atoms)
        return structure

    # ------------------------------------------------------------ stream
    def poll(self) -> None:
        poses = self.follow.poll()
        scene = self.subscriber.scene
        if self._live_wanted and self.follow.current_structure():
            self.live.update(self.structure, float(scene["probe_radius_A"]), poses)

    @property
    def connected(self) -> bool:
        return self.follow.connected

    def lost_for_s(self) -> float:
        """Seconds since a daemon that was sending stopped (0 while it sends or before it did)."""
        return self.follow.lost_for_s()

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
            if self.follow.fetch_error and self.structure is None:
                status += f" ({self.follow.fetch_error})"
        elif self.structure is None:  # it is running (poses arrive): its structure is on the way
            status = f"fetching the structure from {self.ctl}"
        rate = self.follow.haptic_rate_hz()
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
        self.follow.wait_ready(timeout_s)

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
        self.follow.close()
