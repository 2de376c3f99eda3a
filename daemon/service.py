"""`sasprobe daemon`: the one process that owns the device, its lifecycle and its loop.

Threads: the main thread runs the fixed-rate loop (read → haptic force → safety →
write → publish → hand to the recorder) and is the only one that touches the engine
and the PUB socket, and the device but for one exception: the watchdog thread
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
import threading
import time
from pathlib import Path

import numpy as np
from sasprobe.daemon import events
from sasprobe.daemon.buttons import ButtonMap, WorkspaceInputs
from sasprobe.daemon.changes import ChangeQueue
from sasprobe.daemon.config import DaemonConfig, check_config
from sasprobe.daemon.faults import LoopLog, Reconnector
from sasprobe.daemon.loop import (
    FixedRateLoop,
    current_scheduling,
    enter_realtime,
    restore_scheduling,
)
from sasprobe.daemon.marks import Marks, mark_button
from sasprobe.daemon.network import Network
from sasprobe.daemon.recording import replay_scheme
from sasprobe.daemon.recording.replay import REPLAYED_COMMANDS, apply_recorded_event
from sasprobe.daemon.recording.writer import Recorder
from sasprobe.daemon.requests import RequestHandlers
from sasprobe.daemon.scene_message import rotation_rows, scene_message
from sasprobe.daemon.session import open_session
from sasprobe.daemon.structure_worker import StructureWorker
from sasprobe.daemon.watchdog import StallWatchdog
from sasprobe.devices.base import DeviceFault
from sasprobe.devices.workspace.mapping import IDENTITY
from sasprobe.protocol.pose import encode_pose
from sasprobe.protocol.scene import DEFAULT_LIGHTS, encode_scene

from sasprobe import __version__

log = logging.getLogger("sasprobe")

replay_scheme.register()  # the daemon's own recordings, played back as a device

SCENE_INTERVAL_NS = 1_000_000_000  # re-publish the scene at least this often (late joiners)
LATE_READ_PERIODS = 3.0  # a read slower than this many periods counts as failed
SWITCH_INTERVAL_S = 1e-4  # how long another Python thread may hold the GIL before the loop gets it


class Daemon:
    def __init__(self, config: DaemonConfig) -> None:
        self.config = check_config(config)
        start = open_session(config)
        self.structure, self.structure_keep_water, self.device = (
            start.structure,
            start.keep_water,
            start.device,
        )
        self.rate_hz = start.rate_hz
        self.loop = FixedRateLoop(self.rate_hz, spin_s=config.spin_s)
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
        self.last_force_written = np.zeros(3)
        self.write_failures = 0
        self.started_ns = time.monotonic_ns()
        self.scene_revision = 0
        self.scene: dict = {}  # the scene as published (get_scene)
        self._scene_bytes = b""
        self._next_scene_ns = 0
        self.changes = ChangeQueue()  # what the control thread asks of the loop
        self._stop_reason: str | None = None
        self._carry_error: str | None = None  # a failed force write, reported on the next tick
        self._reconnector = Reconnector(self.device)
        self.write_lock = threading.Lock()  # the loop's force writes and the watchdog's zeros
        self.watchdog = StallWatchdog(
            self.device, self.write_lock, self.loop.period_ns, supervise=self._supervise
        )
        self._loop_cpu_clock: int | None = None
        self._cpu_at_reset = 0
        self._network = self.control = self.publisher = None
        self._scheduling = current_scheduling()  # given back when the daemon stops
        try:
            self.realtime = enter_realtime() if config.realtime else False
            self.timing = LoopLog(self.realtime)
            self.device.open()
            self.limits, self.settings, self.pipeline = (
                start.pipeline()
            )  # the opened arm's workspace and limits
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

    def _close_device(self) -> None:
        """Zero force and close the device; a failing device is logged, never raised."""
        try:
            self.device.write_force(np.zeros(3))
            self.last_force_written = np.zeros(3)
        except Exception as exc:
            log.warning("could not write zero force: %s", exc)
        try:
            self.device.close()
        except Exception as exc:
            log.warning("closing the device failed: %s", exc)

    def request_stop(self, reason: str) -> None:
        """End the loop after the current tick (signals, `shutdown`)."""
        self._stop_reason = reason

    def _on_signal(self, signum, frame) -> None:
        self.request_stop(signal.Signals(signum).name)

    def _shutdown(self) -> None:
        """Zero force, close the device, stop serving, finish the recording, report."""
        self._close_device()
        device_last = (
            self.device.last_force_n
        )  # what the device itself holds (None: it cannot tell)
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
            "reason": self._stop_reason,
            "ticks": stats["total"]["ticks"],
            "overruns": stats["total"]["overruns"],
            "faults": self.pipeline.guard.faults,
            "lost_ticks": self.timing.lost,
            "stalls": self.watchdog.as_dict(),
            "last_force_written_n": np.asarray(self.last_force_written).tolist(),
            "device_last_force_n": None
            if device_last is None
            else np.asarray(device_last, dtype=float).tolist(),
            "publisher": publisher_stats,
            "recording": recording,
        }
        if self.config.report:
            Path(self.config.report).write_text(json.dumps({"event": events.STOPPED, **report}))
        events.print_event(events.STOPPED, **report)

    # ------------------------------------------------------------------ the loop
    def run(self) -> int:
        """Run until SIGINT/SIGTERM, `shutdown`, the end of a replay or max_seconds; return 0."""
        previous = {
            sig: signal.signal(sig, self._on_signal) for sig in (signal.SIGINT, signal.SIGTERM)
        }
        old_switch = sys.getswitchinterval()
        sys.setswitchinterval(SWITCH_INTERVAL_S)
        self._loop_cpu_clock = time.pthread_getcpuclockid(
            threading.get_ident()
        )  # readable from other threads
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
        events.print_event(
            events.READY,
            pub=self.publisher.endpoints,
            ctl=self.control.endpoints,
            device=self.device.info.kind,
            rate_hz=self.rate_hz,
            pid=os.getpid(),
            realtime=self.realtime,
        )
        try:
            self._loop()
        finally:
            sys.setswitchinterval(old_switch)
            self.watchdog.stop()
            self._shutdown()
            restore_scheduling(self._scheduling)
            for sig, handler in previous.items():
                signal.signal(sig, handler)
        return 0

    def _supervise(self) -> None:
        """On the watchdog thread, twice a second: the control thread must be alive."""
        if self.control is not None:
            self.control.ensure_running()

    def _loop(self) -> None:
        loop, device, publisher, watchdog, write_lock = (
            self.loop,
            self.device,
            self.publisher,
            self.watchdog,
            self.write_lock,
        )
        clock = time.monotonic_ns
        stall_at = dict(self.config.loop_stalls)  # test hook: tick -> seconds the loop sleeps there
        slow_at = {
            s for tick, n in self.config.slow_reads for s in range(tick, tick + n)
        }  # test hook: slow reads
        # A free-running loop (replay at --speed max) has no period to be late against.
        late_read_ns = int(LATE_READ_PERIODS * loop.period_ns) if loop.period_ns else None
        stop_at_ns = (
            clock() + int(self.config.max_seconds * 1e9) if self.config.max_seconds else None
        )
        self._cpu_at_reset = self.loop_cpu_ns()
        watchdog.start()
        loop.start()
        while self._stop_reason is None:
            tick = loop.wait()
            if self.changes:
                self.changes.apply(tick.seq)
            state = None
            error, self._carry_error = self._carry_error, None
            t_read = clock()
            try:
                state = device.read()
            except DeviceFault as exc:
                error = error or (str(exc) or type(exc).__name__)
            except EOFError:  # a replay reached its end
                self.request_stop("end of replay")
                break
            except Exception as exc:  # a driver bug costs force, never the loop
                error = error or f"device error: {type(exc).__name__}: {exc}"
            if (
                tick.seq in slow_at
            ):  # the read takes a period longer than a read that counts as failed
                time.sleep((LATE_READ_PERIODS + 1) * loop.period_ns / 1e9)
            read_ns = clock() - t_read
            if error is None and late_read_ns is not None and read_ns > late_read_ns:
                error = f"device read took {read_ns / 1e6:.1f} ms"
            for event in device.take_recorded_events():  # a replay repeats its control changes here
                self._apply_recorded_event(event, tick.seq)
            for action, args in self.inputs.tick(
                state.buttons if state is not None else None, tick.start_ns
            ):
                self.workspace_action(action, args, tick.seq)
            if stall_at and tick.seq in stall_at:
                time.sleep(stall_at.pop(tick.seq))
            # A tick the watchdog found overdue counts as late by as long: the guard zeroes it.
            late_periods = max(
                tick.late_periods, device.recorded_late_periods(), watchdog.overdue_periods(clock())
            )
            pipeline = self.pipeline
            was_faulted = pipeline.guard.faulted
            result = pipeline.step(state, error, late_periods)
            with write_lock:
                try:
                    device.write_force(result.force_n)
                    self.last_force_written = result.force_n
                except Exception as exc:
                    self.write_failures += 1
                    self._carry_error = f"force write failed: {exc}"
                stall = watchdog.heartbeat(
                    clock()
                )  # under the lock: the watchdog never zeroes this write
            self.timing.tick(
                tick.start_ns,
                tick.missed,
                error is None and late_periods > pipeline.guard.late_limit_periods,
                result.guard.fault != was_faulted,
                result.guard,
                stall,
            )
            if error is None or state is not None:
                self._reconnector.answered()
            elif self._reconnector.failed(tick.start_ns):
                self.pipeline.reconnected()  # the hand may be anywhere: unseat the proxy, ramp in again
                self.record_control(tick.seq, "reconnect", {})
            now = clock()
            pose = pipeline.pose(tick.seq, state, result, now)
            publisher.publish_pose(encode_pose(pose))
            if self.recorder is not None:
                self.recorder.offer_tick(now, tick.seq, state, error, late_periods, read_ns, pose)
            if publisher.poll_subscriptions(now) or now >= self._next_scene_ns:
                self._publish_scene(now)
            loop.stats.record_work(clock() - tick.start_ns)
            if stop_at_ns is not None and now >= stop_at_ns:
                self.request_stop("time limit")

    def _apply_recorded_event(self, event: dict, seq: int) -> None:
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

    # ------------------------------------------------------------------ state changes (on the loop thread)
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
        )
        self._scene_bytes = encode_scene(self.scene)
        self._next_scene_ns = 0
        if self.recorder is not None:
            self.recorder.offer_json("scene", time.monotonic_ns(), self.scene)

    def _publish_scene(self, now_ns: int) -> None:
        self.publisher.publish_scene(self._scene_bytes)
        self._next_scene_ns = now_ns + SCENE_INTERVAL_NS

    # ------------------------------------------------------------------ recording
    def record_control(self, seq: int, cmd: str, args: dict) -> None:
        if self.recorder is not None:
            self.recorder.offer_json(
                "control", time.monotonic_ns(), {"seq": seq, "cmd": cmd, "args": args}
            )

    def attach_recorder(self, recorder: Recorder, seq: int = 0, fresh_engine=None) -> int:
        """Start recording at this tick from a fresh engine and guard, so the file replays exactly."""
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
        if (
            self.pipeline.view_rotation != IDENTITY
        ):  # the fresh engine took the view over: so will the replay
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

    # ------------------------------------------------------------------ statistics
    def reset_stats(self) -> None:
        self.loop.stats.reset()
        self._cpu_at_reset = self.loop_cpu_ns()

    def loop_cpu_ns(self) -> int:
        clock_id = self._loop_cpu_clock
        return time.clock_gettime_ns(clock_id) if clock_id is not None else time.thread_time_ns()

    def loop_cpu_since_reset_ns(self) -> int:
        return self.loop_cpu_ns() - self._cpu_at_reset
