"""`sasprobe daemon`: the one process that owns the device; its start, its stop and the
state its loop changes.

Threads: the main thread runs the haptic loop (daemon/loop.py: read → haptic force →
safety → write → publish → hand to the recorder) and is the only one that touches the
engine and the PUB socket, and the device but for one exception: the watchdog thread
(daemon/watchdog.py) writes zero force when no tick has completed in time, under the
lock the loop writes with. The control thread answers requests (daemon/requests.py);
anything that changes state is prepared there (parsing a structure, building an engine)
and handed to the loop as a small closure through the daemon's change queue
(daemon/changes.py), applied at the start of the next tick by the state changes below. The
recorder thread writes the MCAP file. ZeroMQ's own I/O threads do the network sending.

A replayed session is a device like any other: the loop asks every device for its
recorded control commands and timing (none, for a live arm), so the loop has no
replay branch.
"""

from __future__ import annotations

import gc
import json
import logging
import os
import signal
import sys
import time
from pathlib import Path

import numpy as np
from sasprobe.daemon import stdout_events
from sasprobe.daemon.buttons import ButtonMap, WorkspaceInputs
from sasprobe.daemon.changes import ChangeQueue
from sasprobe.daemon.config import DaemonConfig, check_config
from sasprobe.daemon.loop import HapticLoop
from sasprobe.daemon.marks import Marks, mark_button
from sasprobe.daemon.network import Network
from sasprobe.daemon.realtime import current_scheduling, enter_realtime, restore_scheduling
from sasprobe.daemon.recording import replay_scheme
from sasprobe.daemon.recording.replay import REPLAYED_COMMANDS, apply_recorded_event
from sasprobe.daemon.recording.writer import Recorder
from sasprobe.daemon.requests import RequestHandlers
from sasprobe.daemon.scene_message import rotation_rows, scene_message
from sasprobe.daemon.session_setup import prepare_session
from sasprobe.daemon.structure_worker import StructureWorker
from sasprobe.devices.workspace.mapping import IDENTITY
from sasprobe.protocol.scene import DEFAULT_LIGHTS, encode_scene

from sasprobe import __version__

log = logging.getLogger("sasprobe")

replay_scheme.register()  # the daemon's own recordings, played back as a device

SCENE_INTERVAL_NS = 1_000_000_000  # re-publish the scene at least this often (late joiners)
SUBSCRIPTIONS_POLL_NS = 5_000_000  # look for new subscribers this often (each look costs µs)
SWITCH_INTERVAL_S = 1e-4  # how long another Python thread may hold the GIL before the loop gets it


class Daemon:
    def __init__(self, config: DaemonConfig) -> None:
        self.config = check_config(config)
        setup = prepare_session(config)
        self.structure = setup.structure
        self.structure_keep_water = setup.keep_water
        self.device = setup.device
        self.rate_hz = setup.rate_hz
        self.clip_planes: list[list[float]] = []
        self.lights = json.loads(json.dumps(DEFAULT_LIGHTS))
        self.nav_cube_enabled = True
        self.color_scheme = config.color_scheme
        self.marks = Marks()  # daemon/marks.py drops them
        self.recorder: Recorder | None = None
        self.requests = RequestHandlers(self)
        self.inputs = WorkspaceInputs(
            ButtonMap.from_options(config.buttons),
            map_device_buttons=self.device.recorded_session() is None,
        )
        self.structure_worker = StructureWorker()  # `load` parses there, started on first use
        self.started_ns = time.monotonic_ns()
        self.scene_revision = 0
        self.scene: dict = {}  # the scene as published (get_scene)
        self._scene_bytes = b""
        self._next_scene_ns = 0
        self._next_poll_ns = 0
        self.changes = ChangeQueue()  # what the control thread asks of the loop
        self._network = self.control = self.publisher = None
        self._scheduling = current_scheduling()  # given back when the daemon stops
        self._device_opened = False  # a device whose open() failed holds no force of ours
        try:
            self.realtime = enter_realtime() if config.realtime else False
            self.loop = HapticLoop(self, self.rate_hz, self.realtime)
            self.device.open()
            self._device_opened = True
            # the opened arm's workspace and limits
            self.limits, self.settings, self.pipeline = setup.build_pipeline()
            self._open_network()
            self.rebuild_scene()
            if config.record:
                self.attach_recorder(Recorder(config.record, self._recording_metadata()))
        except BaseException:
            self._close_network()
            self._close_device()
            restore_scheduling(self._scheduling)
            raise

    # ------------------------------------------------------------------ start and stop
    def _open_network(self) -> None:
        self._network = Network(self.config, self.requests.handle)
        self.publisher, self.control = self._network.publisher, self._network.control

    def _close_network(self) -> None:
        """Stop serving (safe to repeat)."""
        if self._network is not None:
            self._network.close()
        self._network = self.control = self.publisher = None

    def _close_device(self) -> bool:
        """Zero force and close the device; True when the zero was written. A failing device
        is logged, never raised. A device that did not open was sent no force, and its open
        error is the one line said."""
        zeroed = False
        try:
            if self._device_opened:
                self.device.write_force(np.zeros(3))
                zeroed = True
        except Exception as exc:
            log.warning("could not write zero force: %s", exc)
        try:
            self.device.close()
        except Exception as exc:
            log.warning("closing the device failed: %s", exc)
        return zeroed

    def request_stop(self, reason: str) -> None:
        """End the loop after the current tick (signals, `shutdown`)."""
        self.loop.request_stop(reason)

    def _on_signal(self, signum, frame) -> None:
        self.request_stop(signal.Signals(signum).name)

    def _shutdown(self) -> None:
        """Zero force, close the device, stop serving, finish the recording, report."""
        zeroed = self._close_device()
        device_last = self.device.last_force_n  # what the device holds (None: it cannot tell)
        last_written = np.zeros(3) if zeroed else self.loop.last_force_written
        publisher_stats = {
            "poses_sent": self.publisher.poses_sent,
            "subscribers": self.publisher.subscribers,
        }
        self._close_network()
        self.structure_worker.close()
        recording = None
        if self.recorder is not None:
            recorder, self.recorder = self.recorder, None
            recording = recorder.close().as_dict()
        stats = self.loop.stats.summary()
        report = {
            "reason": self.loop.stop_reason,
            "ticks": stats["total"]["ticks"],
            "overruns": stats["total"]["overruns"],
            "faults": self.pipeline.guard.faults,
            "lost_ticks": self.loop.timing.lost,
            "stalls": self.loop.watchdog.as_dict(),
            "last_force_written_n": np.asarray(last_written).tolist(),
            "device_last_force_n": None
            if device_last is None
            else np.asarray(device_last, dtype=float).tolist(),
            "publisher": publisher_stats,
            "recording": recording,
        }
        if self.config.report:
            Path(self.config.report).write_text(
                json.dumps({"event": stdout_events.STOPPED, **report})
            )
        stdout_events.print_event(stdout_events.STOPPED, **report)

    # ------------------------------------------------------------------ run
    def run(self) -> int:
        """Run until SIGINT/SIGTERM, `shutdown`, the end of a replay or max_seconds; return 0."""
        previous = {
            sig: signal.signal(sig, self._on_signal) for sig in (signal.SIGINT, signal.SIGTERM)
        }
        old_switch = sys.getswitchinterval()
        sys.setswitchinterval(SWITCH_INTERVAL_S)
        self.control.start()
        gc.collect()
        gc.freeze()  # start-up objects leave the collector's view: later collections stay short
        log.info(
            "daemon: pose+scene on %s, control on %s, device %s, %s",
            ", ".join(self.publisher.endpoints),
            ", ".join(self.control.endpoints),
            self.device.info.model,
            f"{self.rate_hz:g} Hz" if self.rate_hz else "free-running",
        )
        stdout_events.print_event(
            stdout_events.READY,
            pub=self.publisher.endpoints,
            ctl=self.control.endpoints,
            device=self.device.info.kind,
            rate_hz=self.rate_hz,
            pid=os.getpid(),
            realtime=self.realtime,
        )
        try:
            self.loop.run()
        finally:
            sys.setswitchinterval(old_switch)
            self._shutdown()
            restore_scheduling(self._scheduling)
            for sig, handler in previous.items():
                signal.signal(sig, handler)
        return 0

    def supervise(self) -> None:
        """On the watchdog thread, twice a second: the control thread must be alive."""
        if self.control is not None:
            self.control.ensure_running()

    # ---------------------------------------------------- state changes (on the loop thread)
    def replay_control(self, event: dict, seq: int) -> None:
        """A replayed control command, applied as it was live."""
        if event.get("cmd") not in REPLAYED_COMMANDS:
            return
        if event["cmd"] == "mark":
            self.marks.restore(event["args"])
        self.structure, self.settings = apply_recorded_event(  # a mark changes neither
            event,
            self.pipeline,
            self.structure,
            self.settings,
            self.limits,
            self.device.recorded_session().structure,
        )
        if event["cmd"] == "load" and self.recorder is not None:
            self.recorder.offer_structure(
                time.monotonic_ns(), self.structure.name, self.structure.source_bytes
            )
        self.record_control(seq, event["cmd"], event.get("args", {}))
        self.rebuild_scene()

    def swap_structure(self, structure, keep_water: bool, engine, seq: int) -> int:
        """A new structure and its engine (built off the loop)."""
        self.changes.deferred_release.add(self.structure, self.pipeline.engine)
        self.structure = structure
        self.structure_keep_water = keep_water
        self.pipeline.replace_engine(engine)
        if self.recorder is not None:
            self.recorder.offer_structure(
                time.monotonic_ns(), structure.name, structure.source_bytes
            )
        self.record_control(
            seq,
            "load",
            {"sha256": structure.sha256, "name": structure.name, "keep_water": keep_water},
        )
        self.rebuild_scene()
        return seq

    def apply_settings(
        self, haptic: dict, scene_only: dict, settings: dict, lights: dict | None, engine, seq: int
    ) -> int:
        """A checked `set` (a new engine when one had to be built)."""
        if engine is not None:
            self.changes.deferred_release.add(self.pipeline.engine)
            self.pipeline.replace_engine(engine)
        elif haptic:
            self.pipeline.engine.update(**haptic)
        self.settings = settings
        self.clip_planes = scene_only.get("clip_planes", self.clip_planes)
        self.lights = lights if lights is not None else self.lights
        self.nav_cube_enabled = scene_only.get("nav_cube_enabled", self.nav_cube_enabled)
        self.color_scheme = scene_only.get("color_scheme", self.color_scheme)
        self.record_control(seq, "set", {**haptic, **scene_only})
        self.rebuild_scene()
        return seq

    def workspace_action(self, action: str, args: dict, seq: int) -> None:
        """A clutch change or a pressed action (device button, window key), recorded."""
        if action == "clutch":
            self.pipeline.set_clutch(args["held"])
        elif action == "recentre":
            self.pipeline.recentre()
        elif action == "mark":
            mark_button(self, seq)  # records its own `mark`
            return
        else:
            return
        self.record_control(seq, action, args)

    def turn_view(self, rotation: tuple[float, ...], seq: int) -> int:
        """The workspace view turned (control `view`); the mapping turns with it."""
        self.pipeline.set_view(rotation)
        self.record_control(seq, "view", {"rotation": rotation_rows(rotation)})
        self.rebuild_scene()
        return seq

    # ------------------------------------------------------------------ scene
    def rebuild_scene(self) -> None:
        """The scene message of the current state; published at the next tick, and recorded."""
        self.scene_revision += 1
        self.scene = scene_message(
            self.scene_revision,
            self.structure,
            self.settings,
            self.nav_cube_enabled,
            self.clip_planes,
            self.lights,
            self.device.info,
            self.rate_hz,
            self.pipeline.view_rotation,
            self.marks,
            self.color_scheme,
            self.loop.pose_every,
        )
        self._scene_bytes = encode_scene(self.scene)
        self._next_scene_ns = 0
        if self.recorder is not None:
            self.recorder.offer_json("scene", time.monotonic_ns(), self.scene)

    def publish_scene_when_due(self, now_ns: int) -> None:
        """On the loop thread: the scene to a subscriber who just joined, after a change, and
        every SCENE_INTERVAL_NS for those who missed it. Subscriptions are looked for every
        SUBSCRIPTIONS_POLL_NS, not every tick."""
        if now_ns < self._next_poll_ns and now_ns < self._next_scene_ns:
            return
        self._next_poll_ns = now_ns + SUBSCRIPTIONS_POLL_NS
        if self.publisher.poll_subscriptions(now_ns) or now_ns >= self._next_scene_ns:
            self.publisher.publish_scene(self._scene_bytes)
            self._next_scene_ns = now_ns + SCENE_INTERVAL_NS

    # ------------------------------------------------------------------ recording
    def record_control(self, seq: int, cmd: str, args: dict) -> None:
        if self.recorder is not None:
            self.recorder.offer_json(
                "control", time.monotonic_ns(), {"seq": seq, "cmd": cmd, "args": args}
            )

    def attach_recorder(self, recorder: Recorder, seq: int = 0, fresh_engine=None) -> int:
        """Start recording at this tick from a fresh engine and guard, so the file replays
        exactly."""
        if fresh_engine is not None:
            self.pipeline.restart(fresh_engine)
        self.recorder = recorder
        recorder.offer_structure(
            time.monotonic_ns(), self.structure.name, self.structure.source_bytes
        )
        self.record_control(
            seq,
            "start",
            {
                "settings": self.settings,
                "structure_sha256": self.structure.sha256,
                "structure_name": self.structure.name,
                "keep_water": self.structure_keep_water,
                "rate_hz": self.rate_hz,
                "device": self.device.info.as_dict(),
            },
        )
        # the fresh engine took the view over: so will the replay
        if self.pipeline.view_rotation != IDENTITY:
            self.record_control(
                seq, "view", {"rotation": rotation_rows(self.pipeline.view_rotation)}
            )
        if self.pipeline.clutched:
            self.record_control(seq, "clutch", {"held": True})
        self.rebuild_scene()
        return seq

    def detach_recorder(self, seq: int) -> Recorder | None:
        recorder, self.recorder = self.recorder, None
        if recorder is not None:
            recorder.offer_json(
                "control", time.monotonic_ns(), {"seq": seq, "cmd": "record_stop", "args": {}}
            )
        return recorder

    def new_recorder(self, path: str | Path) -> Recorder:
        return Recorder(path, self._recording_metadata())

    def _recording_metadata(self) -> dict:
        return {
            "daemon_version": __version__,
            "device": self.config.device,
            "rate_hz": self.rate_hz,
            "started_unix_s": time.time(),
        }
