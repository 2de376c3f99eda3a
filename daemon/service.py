"""`sasprobe daemon`: the one process that owns the device.

Threads: the main thread runs the fixed-rate loop (read → haptic force → safety →
write → publish → hand to the recorder) and is the only one that touches the device,
the engine and the PUB socket. The control thread answers requests; anything that
changes state is prepared there (parsing a structure, building an engine) and handed
to the loop as a small closure, applied at the start of the next tick. The recorder
thread writes the MCAP file. ZeroMQ's own I/O threads do the network sending.
"""

from __future__ import annotations

import collections
import gc
import json
import logging
import os
import signal
import sys
import threading
import time
from concurrent.futures import Future, TimeoutError as FutureTimeout
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from sasprobe import __version__
from sasprobe.daemon.control import ControlServer
from sasprobe.daemon.engine import HapticBackend, apply_recorded_event, needs_rebuild, split_changes
from sasprobe.daemon.loop import FixedRateLoop, enter_realtime
from sasprobe.daemon.pipeline import HapticPipeline
from sasprobe.daemon.publisher import Publisher
from sasprobe.daemon.recorder import Recorder
from sasprobe.daemon.safety import SafetyGuard
from sasprobe.devices.base import DeviceFault
from sasprobe.errors import UserError
from sasprobe.protocol.control import Reply, Request
from sasprobe.protocol.endpoints import DEFAULT_CTL_ENDPOINT, DEFAULT_PUB_ENDPOINT, parse_endpoint
from sasprobe.protocol.pose import encode_pose
from sasprobe.protocol.scene import DEFAULT_LIGHTS, SCENE_VERSION, encode_scene, merge_lights

log = logging.getLogger("sasprobe")

SCENE_INTERVAL_NS = 1_000_000_000  # re-publish the scene at least this often (late joiners)
RECONNECT_AFTER_NS = 100_000_000  # a device failing this long gets reconnect() (a blip does not)
RECONNECT_INTERVAL_NS = 500_000_000  # between reconnect attempts while the device is gone
LATE_READ_PERIODS = 3.0  # a read slower than this many periods counts as failed
SUBMIT_TIMEOUT_S = 5.0
SWITCH_INTERVAL_S = 1e-4  # how long another Python thread may hold the GIL before the loop gets it


@dataclass
class DaemonConfig:
    device: str = "sim"
    molecule: str | None = None
    keep_water: bool = False
    rate_hz: float | None = 1000.0  # None: as fast as possible (replay --speed max)
    pub: list[str] = field(default_factory=lambda: [DEFAULT_PUB_ENDPOINT])
    ctl: list[str] = field(default_factory=lambda: [DEFAULT_CTL_ENDPOINT])
    record: str | None = None
    keys: str | None = None
    settings: dict = field(default_factory=dict)  # haptic settings given on the command line
    speed: float | None = 1.0  # replay speed (None: max)
    seed: int = 0
    spin_s: float = 200e-6
    report: str | None = None  # write a JSON exit report here
    max_seconds: float | None = None  # stop by itself after this long (benchmarks, demos)
    realtime: bool = False  # SCHED_FIFO for the loop and ZeroMQ's I/O thread
    faults: list[str] = field(default_factory=list)  # simulated-arm fault injection, e.g. "nan@900+5"


def check_bind_security(endpoints: list[str], keys_dir: str | None) -> None:
    """Refuse to expose the daemon beyond this machine without CURVE keys."""
    for text in endpoints:
        endpoint = parse_endpoint(text)
        if not endpoint.is_loopback and keys_dir is None:
            raise UserError(
                f"refusing to bind {text} without encryption: an address other machines can reach needs "
                f"--keys DIR (CURVE keys with a client allow-list; create them with `sasprobe keys DIR`)"
            )


class FaultLog:
    """Log fault transitions without flooding: at most one line per second, with a count."""

    def __init__(self, interval_ns: int = 1_000_000_000) -> None:
        self.interval_ns = interval_ns
        self._last_ns = -interval_ns
        self._suppressed = 0

    def note(self, reason: str | None, now_ns: int) -> None:
        if now_ns - self._last_ns < self.interval_ns:
            self._suppressed += 1
            return
        more = f" ({self._suppressed} more fault changes in the last second)" if self._suppressed else ""
        if reason is None:
            log.warning("device fault cleared, force back on%s", more)
        else:
            log.warning("device fault: %s; force zeroed%s", reason, more)
        self._last_ns = now_ns
        self._suppressed = 0


class Daemon:
    def __init__(self, config: DaemonConfig, backend=None) -> None:
        self.config = config
        self.backend = backend or HapticBackend()
        check_bind_security(config.pub + config.ctl, config.keys)
        if config.record and Path(config.record).exists():
            raise UserError(f"{config.record}: already exists; record to a new file")
        self._open_device_and_engine()
        self.loop = FixedRateLoop(self.rate_hz, spin_s=config.spin_s)
        self.clip_planes: list[list[float]] = []
        self.lights = json.loads(json.dumps(DEFAULT_LIGHTS))
        self.lights["probe"]["radius_A"] = self.settings["probe_radius_A"]
        self.nav_cube_enabled = True
        self.recorder: Recorder | None = None
        self.last_force_written = np.zeros(3)
        self.write_failures = 0
        self._pending: collections.deque = collections.deque()  # (closure, Future) for the loop
        self._stop_reason: str | None = None
        self._scene_revision = 0
        self._scene_bytes = b""
        self._scene_dict: dict = {}
        self._scene_cube_half: float | None = None
        self._next_scene_ns = 0
        self._started_ns = time.monotonic_ns()
        self._carry_error: str | None = None  # a failed force write, reported on the next tick
        self._last_reconnect_ns = 0
        self._failing_since_ns: int | None = None
        self._fault_log = FaultLog()
        self._loop_cpu_clock: int | None = None
        self._cpu_at_reset = 0
        try:
            self.realtime = enter_realtime() if config.realtime else False
            self.device.open()
            self._open_network()
            self._rebuild_scene()
            if config.record:
                self._attach_recorder(Recorder(config.record, self._recording_metadata()))
        except BaseException:
            self._close_network()
            self._close_device()
            raise

    def _open_device_and_engine(self) -> None:
        """The structure, the (unopened) device, the validated settings and the engine."""
        from sasprobe.devices.registry import open_device, parse_device_spec
        from sasprobe.molecule import load_structure_or_default, parse_structure

        config = self.config
        replaying = parse_device_spec(config.device)[0] == "replay"
        self.structure = None
        self.structure_keep_water = config.keep_water
        if config.molecule is not None or not replaying:
            self.structure = load_structure_or_default(config.molecule, keep_water=config.keep_water)
        self.device = open_device(config.device, structure=self.structure, rate_hz=config.rate_hz,
                                  seed=config.seed, speed=config.speed, faults=config.faults,
                                  probe_radius_A=config.settings.get("probe_radius_A"),
                                  cube_half_A=config.settings.get("cube_half_A"))
        session = getattr(self.device, "session", None)  # a replay: the recording's start
        settings = dict(config.settings)
        self.rate_hz = config.rate_hz
        if session is not None:
            if self.structure is None:
                self.structure = parse_structure(session.structure_bytes, name=session.structure_name,
                                                 source=f"{config.device} (recorded)", keep_water=session.keep_water)
                self.structure_keep_water = session.keep_water
            settings = {**session.settings, **settings}
            self.rate_hz = None if config.speed is None else session.rate_hz * config.speed
        self.limits = self.device.info.limits
        self.settings = self.backend.validate(settings, self.limits)
        self.pipeline = HapticPipeline(self.backend.build(self.structure, self.limits, self.settings),
                                       SafetyGuard(self.limits))

    def _open_network(self) -> None:
        import zmq

        from sasprobe.protocol.security import load_server_keys, start_authenticator

        keys = load_server_keys(Path(self.config.keys)) if self.config.keys else None
        self.context = zmq.Context()  # its I/O thread inherits the loop's scheduling (--realtime)
        self.auth = start_authenticator(self.context, keys) if keys else None
        try:
            self.publisher = Publisher(self.context, self.config.pub, keys)
            self.control = ControlServer(self.context, self.config.ctl, self.handle, keys)
        except zmq.ZMQError as exc:
            endpoints = " / ".join(self.config.pub + self.config.ctl)
            raise UserError(f"cannot bind {endpoints}: {exc}") from None

    def _close_network(self) -> None:
        """Stop the control thread, close the sockets and the authenticator (safe to repeat)."""
        if getattr(self, "control", None) is not None:
            self.control.stop()
        if getattr(self, "publisher", None) is not None:
            self.publisher.close()
        if getattr(self, "auth", None) is not None:
            self.auth.stop()
        if getattr(self, "context", None) is not None:
            self.context.term()
        self.control = self.publisher = self.auth = self.context = None

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

    # ------------------------------------------------------------------ the loop
    def run(self) -> int:
        """Run until SIGINT/SIGTERM, `shutdown`, the end of a replay or max_seconds; return 0."""
        previous = {sig: signal.signal(sig, self._on_signal) for sig in (signal.SIGINT, signal.SIGTERM)}
        old_switch = sys.getswitchinterval()
        sys.setswitchinterval(SWITCH_INTERVAL_S)
        self._loop_cpu_clock = time.pthread_getcpuclockid(threading.get_ident())  # readable from other threads
        self.control.start()
        gc.collect()
        gc.freeze()  # start-up objects leave the collector's view: later collections stay short
        log.info("daemon: pose+scene on %s, control on %s, device %s, %s",
                 ", ".join(self.publisher.endpoints), ", ".join(self.control.endpoints),
                 self.device.info.model, f"{self.rate_hz:g} Hz" if self.rate_hz else "free-running")
        print(json.dumps({"event": "ready", "pub": self.publisher.endpoints, "ctl": self.control.endpoints,
                          "device": self.device.info.kind, "rate_hz": self.rate_hz, "pid": os.getpid(),
                          "realtime": self.realtime}),
              flush=True)
        try:
            self._loop()
        finally:
            sys.setswitchinterval(old_switch)
            self._shutdown()
            for sig, handler in previous.items():
                signal.signal(sig, handler)
        return 0

    def _on_signal(self, signum, frame) -> None:
        self._stop_reason = signal.Signals(signum).name

    def _loop(self) -> None:
        loop, device, pipeline, publisher = self.loop, self.device, self.pipeline, self.publisher
        clock = time.monotonic_ns
        take_events = getattr(device, "take_events", None)  # a replay's recorded control commands
        recorded_lateness = getattr(device, "recorded_late_periods", None)  # and its recorded timing
        # A free-running loop (replay at --speed max) has no period to be late against.
        late_read_ns = int(LATE_READ_PERIODS * loop.period_ns) if loop.period_ns else None
        stop_at_ns = clock() + int(self.config.max_seconds * 1e9) if self.config.max_seconds else None
        self._cpu_at_reset = self._loop_cpu_ns()
        loop.start()
        while self._stop_reason is None:
            tick = loop.wait()
            if self._pending:
                self._apply_pending(tick.seq)
            pipeline = self.pipeline
            state = None
            error, self._carry_error = self._carry_error, None
            t_read = clock()
            try:
                state = device.read()
            except DeviceFault as exc:
                error = error or (str(exc) or type(exc).__name__)
            except EOFError:  # a replay reached its end
                self._stop_reason = "end of replay"
                break
            except Exception as exc:  # a driver bug costs force, never the loop
                error = error or f"device error: {type(exc).__name__}: {exc}"
            read_ns = clock() - t_read
            if error is None and late_read_ns is not None and read_ns > late_read_ns:
                error = f"device read took {read_ns / 1e6:.1f} ms"
            late_periods = tick.late_periods
            if take_events is not None:
                for event in take_events():
                    self._apply_recorded_event(event, tick.seq)
                pipeline = self.pipeline
                late_periods = max(late_periods, recorded_lateness())
            was_faulted = pipeline.guard.faulted
            result = pipeline.step(state, error, late_periods)
            try:
                device.write_force(result.force_n)
                self.last_force_written = result.force_n
            except Exception as exc:
                self.write_failures += 1
                self._carry_error = f"force write failed: {exc}"
            if result.guard.fault != was_faulted:
                self._fault_log.note(result.guard.reason if result.guard.fault else None, tick.start_ns)
            if error is None or state is not None:
                self._failing_since_ns = None
            elif take_events is None:  # a replay repeats the recorded reconnects instead
                self._maybe_reconnect(tick.seq, tick.start_ns)
            now = clock()
            pose = pipeline.pose(tick.seq, state, result, now)
            publisher.publish_pose(encode_pose(pose))
            if self.recorder is not None:
                self.recorder.offer_tick(now, tick.seq, state, error, late_periods, read_ns, pose)
            cube_half = pose.cube_half_A
            if publisher.poll_subscriptions() or now >= self._next_scene_ns or cube_half != self._scene_cube_half:
                if cube_half != self._scene_cube_half:
                    self._scene_cube_half = cube_half
                    self._rebuild_scene()
                self._publish_scene(now)
            loop.stats.record_work(clock() - tick.start_ns)
            if stop_at_ns is not None and now >= stop_at_ns:
                self._stop_reason = "time limit"

    def _maybe_reconnect(self, seq: int, now_ns: int) -> None:
        if self._failing_since_ns is None:
            self._failing_since_ns = now_ns
        if now_ns - self._failing_since_ns < RECONNECT_AFTER_NS or now_ns - self._last_reconnect_ns < RECONNECT_INTERVAL_NS:
            return
        self._last_reconnect_ns = now_ns
        try:
            self.device.reconnect()
        except DeviceFault as exc:
            log.info("device reconnect failed: %s", exc)
            return
        log.warning("device reconnected")
        self.pipeline.reconnected()
        self._record_control(seq, "reconnect", {})

    def _shutdown(self) -> None:
        """Zero force, close the device, stop serving, finish the recording, report."""
        self._close_device()
        device_last = getattr(self.device, "last_force_n", None)  # what the device itself holds
        publisher_stats = {"poses_sent": self.publisher.poses_sent, "subscribers": self.publisher.subscribers}
        self._close_network()
        recording = None
        if self.recorder is not None:
            recorder, self.recorder = self.recorder, None
            recording = recorder.close().as_dict()
        stats = self.loop.stats.summary()
        report = {
            "event": "stopped",
            "reason": self._stop_reason,
            "ticks": stats["total"]["ticks"],
            "overruns": stats["total"]["overruns"],
            "faults": self.pipeline.guard.faults,
            "last_force_written_n": np.asarray(self.last_force_written).tolist(),
            "device_last_force_n": None if device_last is None else np.asarray(device_last, dtype=float).tolist(),
            "publisher": publisher_stats,
            "recording": recording,
        }
        if self.config.report:
            Path(self.config.report).write_text(json.dumps(report))
        print(json.dumps(report), flush=True)

    # ------------------------------------------------------------------ scene
    def _rebuild_scene(self) -> None:
        s = self.settings
        half = self._scene_cube_half if self._scene_cube_half is not None else (s.get("cube_half_A") or 0.0)
        self._scene_revision += 1
        scene = {
            "version": SCENE_VERSION,
            "revision": self._scene_revision,
            "daemon_version": __version__,
            "structure": {"name": self.structure.name, "sha256": self.structure.sha256,
                          "n_atoms": self.structure.n_atoms},
            "probe_radius_A": s["probe_radius_A"],
            "nav_cube": {"half_A": float(half), "enabled": self.nav_cube_enabled},
            "clip_planes": self.clip_planes,
            "lights": self.lights,
            "device": self.device.info.as_dict(),
            "haptics": {"method": s["method"], "stiffness_n_per_mm": s["stiffness_n_per_mm"],
                        "damping_n_s_per_m": s["damping_n_s_per_m"]},
            "rate_hz": self.rate_hz,
        }
        self._scene_bytes = encode_scene(scene)
        self._scene_dict = scene
        self._next_scene_ns = 0  # publish at the next tick
        if self.recorder is not None:
            self.recorder.offer_json("scene", time.monotonic_ns(), scene)

    def _publish_scene(self, now_ns: int) -> None:
        self.publisher.publish_scene(self._scene_bytes)
        self._next_scene_ns = now_ns + SCENE_INTERVAL_NS

    # ------------------------------------------------------------------ control
    def handle(self, request: Request) -> Reply:
        """Runs on the control thread."""
        handler = getattr(self, f"_cmd_{request.cmd}")
        result, data = handler(request)
        return Reply(ok=True, result=result, data=data)

    def _submit(self, fn):
        """Run fn on the loop thread at the start of the next tick and return its result."""
        future: Future = Future()
        self._pending.append((fn, future))
        try:
            return future.result(timeout=SUBMIT_TIMEOUT_S)
        except FutureTimeout:
            raise UserError("the daemon loop did not take the change in time (is it shutting down?)") from None

    def _apply_pending(self, seq: int) -> None:
        while self._pending:
            fn, future = self._pending.popleft()
            try:
                future.set_result(fn(seq))
            except Exception as exc:
                future.set_exception(exc)

    def _record_control(self, seq: int, cmd: str, args: dict) -> None:
        if self.recorder is not None:
            self.recorder.offer_json("control", time.monotonic_ns(), {"seq": seq, "cmd": cmd, "args": args})

    def _cmd_ping(self, request):
        return {"pong": True, "t_ns": time.monotonic_ns(), "daemon_version": __version__}, None

    def _cmd_status(self, request):
        stats = self.loop.stats
        if request.args.get("reset_stats"):
            self._submit(lambda seq: self._reset_stats())
        summary = stats.summary()
        cpu_s = (self._loop_cpu_ns() - self._cpu_at_reset) / 1e9
        summary["cpu_percent"] = 100.0 * cpu_s / summary["window_s"] if summary["window_s"] > 0 else None
        summary["target_rate_hz"] = self.rate_hz
        guard = self.pipeline.guard
        rec = self.recorder
        return {
            "daemon_version": __version__,
            "pid": os.getpid(),
            "uptime_s": (time.monotonic_ns() - self._started_ns) / 1e9,
            "loop": summary,
            "device": {**self.device.info.as_dict(), "faulted": guard.faulted, "faults": guard.faults,
                       "fault_ticks": guard.fault_ticks, "last_fault": guard.last_reason,
                       "clamped_ticks": guard.clamped_ticks,
                       "write_failures": self.write_failures},
            "structure": {"name": self.structure.name, "sha256": self.structure.sha256,
                          "n_atoms": self.structure.n_atoms},
            "publisher": {"endpoints": self.publisher.endpoints, "subscribers": self.publisher.subscribers,
                          "poses_sent": self.publisher.poses_sent, "scenes_sent": self.publisher.scenes_sent,
                          "send_failures": self.publisher.send_failures},
            "control": {"endpoints": self.control.endpoints, "requests": self.control.requests,
                        "errors": self.control.errors},
            "recording": None if rec is None else {**rec.stats().as_dict(), "error": rec.error},
        }, None

    def _reset_stats(self) -> None:
        self.loop.stats.reset()
        self._cpu_at_reset = self._loop_cpu_ns()

    def _loop_cpu_ns(self) -> int:
        clock_id = self._loop_cpu_clock
        return time.clock_gettime_ns(clock_id) if clock_id is not None else time.thread_time_ns()

    def _cmd_get_scene(self, request):
        return self._scene_dict, None

    def _cmd_get_structure(self, request):
        s = self.structure
        return {"name": s.name, "sha256": s.sha256, "n_atoms": s.n_atoms, "bytes": len(s.source_bytes),
                "gzip": s.source_bytes[:2] == b"\x1f\x8b", "keep_water": self.structure_keep_water}, s.source_bytes

    def _cmd_load(self, request):
        from sasprobe.molecule import load_structure, parse_structure

        keep_water = request.args.get("keep_water", False)
        if request.data is not None:
            name = request.args.get("name") or "uploaded"
            structure = parse_structure(request.data, name=name, source=f"control:{name}", keep_water=keep_water)
        else:
            structure = load_structure(request.args["path"], keep_water=keep_water)
        engine = self.backend.build(structure, self.limits, self.settings)  # off the loop: grids take time

        def swap(seq: int):
            self.structure = structure
            self.structure_keep_water = keep_water
            self.pipeline.replace_engine(engine)
            self._scene_cube_half = None
            if self.recorder is not None:
                self.recorder.offer_structure(time.monotonic_ns(), structure.name, structure.source_bytes)
            self._record_control(seq, "load", {"sha256": structure.sha256, "name": structure.name,
                                               "keep_water": keep_water})
            self._rebuild_scene()
            return seq

        seq = self._submit(swap)
        log.warning("loaded %s (%d atoms) at tick %d", structure.source, structure.n_atoms, seq)
        return {"structure": {"name": structure.name, "sha256": structure.sha256, "n_atoms": structure.n_atoms},
                "seq": seq}, None

    def _cmd_set(self, request):
        changes = dict(request.args)
        haptic, scene_only = split_changes(changes)
        new_settings = self.backend.validate({**self.settings, **haptic}, self.limits) if haptic else self.settings
        lights = merge_lights(self.lights, scene_only["lights"]) if "lights" in scene_only else None
        engine = self.backend.build(self.structure, self.limits, new_settings) if needs_rebuild(haptic) else None

        def apply(seq: int):
            if engine is not None:
                self.pipeline.replace_engine(engine)
            elif haptic:
                self.pipeline.engine.update(**haptic)
            self.settings = new_settings
            if "clip_planes" in scene_only:
                self.clip_planes = scene_only["clip_planes"]
            if lights is not None:
                self.lights = lights
            if "nav_cube_enabled" in scene_only:
                self.nav_cube_enabled = scene_only["nav_cube_enabled"]
            if "cube_half_A" in haptic:
                self._scene_cube_half = None
            self._record_control(seq, "set", {**haptic, **scene_only})
            self._rebuild_scene()
            return seq

        seq = self._submit(apply)
        return {"seq": seq, "settings": new_settings, "revision": self._scene_revision}, None

    def _apply_recorded_event(self, event: dict, seq: int) -> None:
        """A replay device's recorded control command, applied as it was live."""
        if event.get("cmd") not in ("set", "load", "reconnect"):
            return
        self.structure, self.settings = apply_recorded_event(
            event, self.pipeline, self.backend, self.structure, self.settings, self.limits,
            self.device.session.structure)
        if event["cmd"] == "load" and self.recorder is not None:
            self.recorder.offer_structure(time.monotonic_ns(), self.structure.name, self.structure.source_bytes)
        self._record_control(seq, event["cmd"], event.get("args", {}))
        self._rebuild_scene()

    def _cmd_record_start(self, request):
        if self.recorder is not None:
            raise UserError(f"already recording to {self.recorder.path}")
        recorder = Recorder(request.args["path"], self._recording_metadata())
        engine = self.backend.build(self.structure, self.limits, self.settings)  # the replay starts from this
        try:
            seq = self._submit(lambda seq: self._attach_recorder(recorder, seq, engine))
        except UserError:
            recorder.close()
            raise
        return {"path": str(recorder.path), "seq": seq}, None

    def _attach_recorder(self, recorder: Recorder, seq: int = 0, fresh_engine=None) -> int:
        """Start recording at this tick from a fresh engine and guard, so the file replays exactly."""
        if fresh_engine is not None:
            self.pipeline.restart(fresh_engine)
        self.recorder = recorder
        recorder.offer_structure(time.monotonic_ns(), self.structure.name, self.structure.source_bytes)
        self._record_control(seq, "start", {
            "settings": self.settings, "structure_sha256": self.structure.sha256,
            "structure_name": self.structure.name, "keep_water": self.structure_keep_water,
            "rate_hz": self.rate_hz, "device": self.device.info.as_dict(),
        })
        self._rebuild_scene()
        return seq

    def _cmd_record_stop(self, request):
        recorder = self._submit(lambda seq: self._detach_recorder(seq))
        if recorder is None:
            raise UserError("not recording")
        return recorder.close().as_dict(), None

    def _detach_recorder(self, seq: int):
        recorder, self.recorder = self.recorder, None
        if recorder is not None:
            recorder.offer_json("control", time.monotonic_ns(), {"seq": seq, "cmd": "record_stop", "args": {}})
        return recorder

    def _cmd_shutdown(self, request):
        self._stop_reason = "shutdown request"
        return {"stopping": True}, None

    def _recording_metadata(self) -> dict:
        return {"daemon_version": __version__, "device": self.config.device, "rate_hz": self.rate_hz,
                "started_unix_s": time.time()}

