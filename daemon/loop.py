"""The haptic loop: the timer's ticks, and what each tick does, in order.

One tick, on the daemon's main thread (the only one that touches the engine, the PUB
socket and the device, but for the stall watchdog's zero):

1. apply the changes the control thread handed over (daemon/changes.py);
2. read the device: a fault, a read slower than LATE_READ_PERIODS or a driver's bug
   costs this tick's force, never the loop;
3. repeat a replay's recorded control changes, act on buttons and the window's keys;
4. step the haptic pipeline: the engine, then the safety guard (daemon/haptics/);
5. write the force under the lock the watchdog zeroes with, and beat its heartbeat (a
   force the guard withheld goes out as `withhold_force()`: a zero that says nothing of
   where the hand is);
6. log faults and lost ticks; reconnect a device that keeps failing;
7. hand the tick to the recorder (every tick); publish the scene when it is due and the
   pose, on every `pose_every`-th tick only.

Publishing is decimated so that a fast loop keeps little more than read, haptics and
write: above POSE_RATE_HZ only every Nth tick's pose goes out (N = rate // POSE_RATE_HZ,
so subscribers still get poses at POSE_RATE_HZ or more; the scene's `pose_every` says N).
Nothing in the loop waits on the network, the disk or a renderer. The timer is
daemon/timer.py; the state the ticks change (structure, settings, scene, recorder) is
the daemon's (daemon/service.py).
"""

from __future__ import annotations

import threading
import time

import numpy as np
from sasprobe.daemon.faults import LoopLog, Reconnector
from sasprobe.daemon.haptics.pipeline import TickResult
from sasprobe.daemon.timer import FixedRateTimer, LoopStats, Tick
from sasprobe.daemon.watchdog import Stall, StallWatchdog
from sasprobe.devices.base import DeviceFault, DeviceState
from sasprobe.protocol.pose import encode_pose

LATE_READ_PERIODS = 3.0  # a read slower than this many periods counts as failed
POSE_RATE_HZ = 1000.0  # subscribers get a pose at least this often: above it, every Nth tick's


def pose_stride(rate_hz: float | None) -> int:
    """Publish every Nth tick's pose: 1 up to POSE_RATE_HZ (and free-running), else the
    largest N that keeps poses at POSE_RATE_HZ or more."""
    return max(1, int(rate_hz // POSE_RATE_HZ)) if rate_hz else 1


class HapticLoop:
    """The loop of one Daemon: it runs the ticks; the daemon holds the state they change."""

    def __init__(self, daemon, rate_hz: float | None, realtime: bool) -> None:
        config = daemon.config
        self.daemon = daemon
        self.device = daemon.device
        self.timer = FixedRateTimer(rate_hz, spin_s=config.spin_s)
        self.pose_every = pose_stride(rate_hz)
        self.write_lock = threading.Lock()  # the loop's force writes and the watchdog's zeros
        self.watchdog = StallWatchdog(
            self.device, self.write_lock, self.timer.period_ns, supervise=daemon.supervise
        )
        self.timing = LoopLog(realtime)
        self.reconnector = Reconnector(self.device)
        self.stop_reason: str | None = None
        self.last_force_written = np.zeros(3)
        self.write_failures = 0
        self._carry_error: str | None = None  # a failed force write, reported on the next tick
        # A free-running loop (replay at --speed max) has no period to be late against.
        period_ns = self.timer.period_ns
        self._late_read_ns = int(LATE_READ_PERIODS * period_ns) if period_ns else None
        self._cpu_clock: int | None = None
        self._cpu_at_reset = 0
        # Test hooks: the tick -> seconds the loop sleeps there, and the ticks whose read is slow.
        self._stall_at = dict(config.loop_stalls)
        self._slow_at = {s for tick, n in config.slow_reads for s in range(tick, tick + n)}

    @property
    def stats(self) -> LoopStats:
        return self.timer.stats

    def request_stop(self, reason: str) -> None:
        """End the loop after the current tick."""
        self.stop_reason = reason

    def run(self) -> None:
        """Tick until a stop is asked for: a signal, `shutdown`, the end of a replay or
        --seconds."""
        max_seconds = self.daemon.config.max_seconds
        stop_at_ns = time.monotonic_ns() + int(max_seconds * 1e9) if max_seconds else None
        self._cpu_clock = time.pthread_getcpuclockid(threading.get_ident())  # readable elsewhere
        self._cpu_at_reset = self.cpu_ns()
        self.watchdog.start()
        self.timer.start()
        try:
            while self.stop_reason is None:
                try:
                    now = self.tick(self.timer.wait())
                except EOFError:  # a replay reached its end
                    self.request_stop("end of replay")
                    break
                if stop_at_ns is not None and now >= stop_at_ns:
                    self.request_stop("time limit")
        finally:
            self.watchdog.stop()

    def tick(self, tick: Tick) -> int:
        """One tick (EOFError: a replay has no more); returns when it published (ns)."""
        daemon, clock = self.daemon, time.monotonic_ns
        if daemon.changes:
            daemon.changes.apply(tick.seq)
        state, error, read_ns = self._read(tick.seq)
        self._take_inputs(tick, state)
        if self._stall_at and tick.seq in self._stall_at:
            time.sleep(self._stall_at.pop(tick.seq))
        # A tick the watchdog found overdue counts as late by as long: the guard zeroes it.
        late_periods = max(
            tick.late_periods,
            self.device.recorded_late_periods(),
            self.watchdog.overdue_periods(clock()),
        )
        pipeline = daemon.pipeline
        was_faulted = pipeline.guard.faulted
        result = pipeline.step(state, error, late_periods)
        stall = self._write(result)
        self.timing.tick(
            tick.start_ns,
            tick.missed,
            error is None and late_periods > pipeline.guard.late_limit_periods,
            result.guard.fault != was_faulted,
            result.guard,
            stall,
        )
        self._keep_device(tick, state, error)
        now = clock()
        publishing = tick.seq % self.pose_every == 0
        recorder = daemon.recorder
        if publishing or recorder is not None:
            pose = pipeline.pose(tick.seq, state, result, now)
            if recorder is not None:
                recorder.offer_tick(now, tick.seq, state, error, late_periods, read_ns, pose)
            if publishing:
                daemon.publish_scene_when_due(now)
                daemon.publisher.publish_pose(encode_pose(pose))
        self.timer.stats.record_work(clock() - tick.start_ns)
        return now

    def _read(self, seq: int) -> tuple[DeviceState | None, str | None, int]:
        """(the device's state or None, why there is none, how long the read took in ns)."""
        state = None
        error, self._carry_error = self._carry_error, None
        t_read = time.monotonic_ns()
        try:
            state = self.device.read()
        except DeviceFault as exc:
            error = error or (str(exc) or type(exc).__name__)
        except EOFError:
            raise
        except Exception as exc:  # a driver bug costs force, never the loop
            error = error or f"device error: {type(exc).__name__}: {exc}"
        if seq in self._slow_at:  # test hook: a read a period slower than a failed one
            time.sleep((LATE_READ_PERIODS + 1) * self.timer.period_ns / 1e9)
        read_ns = time.monotonic_ns() - t_read
        if error is None and self._late_read_ns is not None and read_ns > self._late_read_ns:
            error = f"device read took {read_ns / 1e6:.1f} ms"
        if error is not None:
            self.timer.stats.failed_reads += 1
        return state, error, read_ns

    def _take_inputs(self, tick: Tick, state: DeviceState | None) -> None:
        """A replay's recorded control changes, then the buttons' and keys' actions."""
        daemon = self.daemon
        for event in self.device.take_recorded_events():
            daemon.replay_control(event, tick.seq)
        buttons = state.buttons if state is not None else None
        for action, args in daemon.inputs.tick(buttons, tick.start_ns):
            daemon.workspace_action(action, args, tick.seq)

    def _write(self, result: TickResult) -> Stall | None:
        """Write the force and beat the watchdog's heartbeat, under the lock the watchdog
        writes zero with; returns the stall the heartbeat ended, if any. A force the guard
        withheld (a fault, a ramp at zero) is `withhold_force()`: no word on the contact."""
        guard = result.guard
        with self.write_lock:
            try:
                if guard.fault or guard.ramp == 0.0:
                    self.device.withhold_force()
                else:
                    self.device.write_force(result.force_n)
                self.last_force_written = result.force_n
            except Exception as exc:
                self.write_failures += 1
                self._carry_error = f"force write failed: {exc}"
            # under the lock: the watchdog never zeroes this write
            return self.watchdog.heartbeat(time.monotonic_ns())

    def _keep_device(self, tick: Tick, state: DeviceState | None, error: str | None) -> None:
        """A device that gave nothing for long gets reconnect(); once it is back the hand may
        be anywhere: the proxy is unseated and forces ramp in again."""
        if error is None or state is not None:
            self.reconnector.answered()
        elif self.reconnector.failed(tick.start_ns):
            self.daemon.pipeline.reconnected()
            self.daemon.record_control(tick.seq, "reconnect", {})

    # ------------------------------------------------------------------ statistics
    def reset_stats(self) -> None:
        self.timer.stats.reset()
        self._cpu_at_reset = self.cpu_ns()

    def cpu_ns(self) -> int:
        """The loop thread's CPU time."""
        clock_id = self._cpu_clock
        return time.clock_gettime_ns(clock_id) if clock_id is not None else time.thread_time_ns()

    def cpu_since_reset_ns(self) -> int:
        return self.cpu_ns() - self._cpu_at_reset
