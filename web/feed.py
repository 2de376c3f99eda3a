"""What the bridge keeps of a daemon's session for its pages: the structure and colour
packets, the scene, whether the daemon is there, and the newest pose.

One thread follows the daemon (protocol/follow.py, as `render --connect` does) and keeps
only the newest pose: a page is sent the newest one when it has drawn the last, so nothing
queues for a slow page. Packets are built on a second thread (the `sas` colours measure the
surface first, which takes seconds on a large structure), so poses keep flowing meanwhile.
The bridge's event loop is told when something every page needs has changed, and about a new
pose only while a page waits for one.
"""

from __future__ import annotations

import json
import logging
import threading
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass

from sasprobe.molecule.residues import touched_label
from sasprobe.protocol.follow import DaemonFollow
from sasprobe.protocol.pose import Pose
from sasprobe.web.packets import colors_packet, effective_scheme, structure_packet

log = logging.getLogger("sasprobe")

POLL_S = 0.05  # while a page waits for a pose, the follow thread waits this long for one
IDLE_S = 0.004  # otherwise it takes in what arrived this often
STOP_S = 30.0  # how long stop() waits for the follow thread (seconds on a loaded machine)


@dataclass(frozen=True)
class Packets:
    """A structure and its colours as pages are sent them (binary packets)."""

    sha256: str
    structure: bytes
    colors_key: tuple  # (sha256, scheme, probe radius for `sas`)
    colors: bytes


class Feed:
    def __init__(self, follow: DaemonFollow) -> None:
        self.follow = follow
        # called (from the follow thread) when the packets, the scene or the daemon's presence
        # changed, and for a pose while `pose_wanted` is set
        self.changed: Callable[[], None] = lambda: None
        self.packets: Packets | None = None
        self.scene_json: str | None = None  # the scene message as pages are sent it
        self.scene_key: tuple | None = None
        self.latest: tuple[Pose, str | None] | None = None  # the newest pose, its touched atom
        self.connected = False
        self.pose_wanted = threading.Event()  # a page waits for a pose newer than it has
        self._structure = None
        self._colors_wanted: tuple | None = None
        self._builder = ThreadPoolExecutor(1, thread_name_prefix="sasprobe-web-packets")
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="sasprobe-web-follow", daemon=True)

    def start(self) -> None:
        self._thread.start()

    def stop(self) -> None:
        self._stop.set()
        self._thread.join(timeout=STOP_S)
        self._builder.shutdown(wait=False, cancel_futures=True)
        if self._thread.is_alive():  # starved of CPU: its sockets go with the process, since
            return  # a ZeroMQ socket closed under the thread using it raises there
        self.follow.close()

    @property
    def rate_hz(self) -> float | None:
        return self.follow.haptic_rate_hz() if self.connected else None

    # ------------------------------------------------------------ the follow thread
    def _run(self) -> None:
        while not self._stop.is_set():
            if self.pose_wanted.is_set():  # a page waits: take the next pose as it comes
                poses = self.follow.poll(POLL_S)
            else:  # the newest pose is all any page will take: look a few times a frame
                self._stop.wait(IDLE_S)
                poses = self.follow.poll()
            news = False
            structure = self.follow.take_new_structure()
            if structure is not None:
                self._structure = structure
                log.info("daemon structure: %s (%d atoms)", structure.name, structure.n_atoms)
            scene = self.follow.subscriber.scene
            if scene is not None:
                key = (scene.get("revision"), scene["structure"]["sha256"])
                if key != self.scene_key:
                    self.scene_json = json.dumps({"type": "scene", "scene": scene})
                    self.scene_key = key
                    news = True
            if (structure is not None or news) and self.follow.current_structure():
                self._want_colors(scene)
            connected = self.follow.connected
            if connected != self.connected:
                self.connected = connected
                news = True
            if poses:
                pose = poses[-1]
                current = self.follow.current_structure()
                label = touched_label(self._structure, pose.touched_atom) if current else None
                self.latest = (pose, label)
                if self.pose_wanted.is_set():
                    self.pose_wanted.clear()
                    news = True
            if news:
                self.changed()

    def _want_colors(self, scene: dict) -> None:
        """Build the packets of the structure in the colours the scene asks for, unless built."""
        wanted = self._colors_key(scene)
        if wanted != self._colors_wanted:
            self._colors_wanted = wanted
            self._builder.submit(self._build, self._structure, wanted)

    def _colors_key(self, scene: dict) -> tuple:
        scheme = effective_scheme(self._structure, scene)
        radius = float(scene["probe_radius_A"]) if scheme == "sas" else None
        return (self._structure.sha256, scheme, radius)

    def _build(self, structure, key: tuple) -> None:
        try:
            packets = self.packets
            if packets is None or packets.sha256 != structure.sha256:
                structure_bytes = structure_packet(structure)
            else:
                structure_bytes = packets.structure
            colors = colors_packet(structure, key[1], key[2])
        except Exception:  # noqa: BLE001 - a page keeps the last packets; the log says why
            log.exception("cannot build the page's packets for %s", structure.name)
            return
        self.packets = Packets(structure.sha256, structure_bytes, key, colors)
        self.changed()
