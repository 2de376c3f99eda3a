"""The loop's fault bookkeeping: logs that do not flood, and when to try reconnect().

A device that fails for RECONNECT_AFTER_NS (a blip does not count) gets `reconnect()`
every RECONNECT_INTERVAL_NS until it answers again. Ticks lost to timing (late starts,
skipped deadlines, stalls) are told once, with what fixes them, rather than once per
fault; a long stall is told with its length. All run on the loop thread and take the
tick's time as an argument.
"""

from __future__ import annotations

import logging

from sasprobe.daemon.realtime import REALTIME_FIX
from sasprobe.devices.base import DeviceFault, HapticDevice

log = logging.getLogger("sasprobe")

RECONNECT_AFTER_NS = 100_000_000  # a device failing this long gets reconnect() (a blip does not)
RECONNECT_INTERVAL_NS = 500_000_000  # between reconnect attempts while the device is gone


class FaultLog:
    """Log fault transitions without flooding: at most one line per second, with a count."""

    def __init__(self, interval_ns: int = 1_000_000_000) -> None:
        self.interval_ns = interval_ns
        self._last_ns = -interval_ns
        self._suppressed = 0

    def note(self, reason: str, now_ns: int) -> None:
        self.say(f"device fault: {reason}; force zeroed", now_ns)

    def cleared(self, reason: str, now_ns: int) -> None:
        self.say(f"device fault cleared ({reason}), force back on", now_ns)

    def say(self, line: str, now_ns: int) -> None:
        if now_ns - self._last_ns < self.interval_ns:
            self._suppressed += 1
            return
        more = f" ({self._suppressed} more in the last second)" if self._suppressed else ""
        log.warning("%s%s", line, more)
        self._last_ns = now_ns
        self._suppressed = 0


# lost ticks within LOST_WINDOW_NS before the loop says so (a hiccup does not count)
LOST_TICKS_WARN = 10
LOST_WINDOW_NS = 1_000_000_000
STALL_LOG_NS = 20_000_000  # a stall this long gets its own line (shorter ones count as lost ticks)


class LoopLog:
    """What the loop says about its ticks: device faults (FaultLog), ticks lost to timing
    (once, with the fix), long stalls (with their length)."""

    def __init__(self, realtime: bool) -> None:
        self.realtime = realtime
        self.lost = 0  # ticks lost to timing since start
        self.warned = False
        self._window: list[tuple[int, int]] = []  # (tick time, lost) within the last window
        self._stalls = FaultLog()
        self._faults = FaultLog()
        # the reason of the fault in progress when it was told (a timing fault is not:
        # lost_ticks tells it), so that its end names it
        self._fault_told: str | None = None

    def tick(
        self, now_ns: int, missed: int, timing_only: bool, fault_changed: bool, guard, stall
    ) -> None:
        """After each tick: `timing_only` when the tick was faulted for lateness alone."""
        self.lost_ticks(now_ns, missed + (1 if timing_only else 0))
        if stall is not None:
            self.stall(stall.length_ns, stall.zeroed_after_ns, now_ns)
        if not fault_changed:
            return
        if guard.fault and not timing_only:
            self._fault_told = guard.reason
            self._faults.note(guard.reason, now_ns)
        elif not guard.fault and self._fault_told is not None:
            self._faults.cleared(self._fault_told, now_ns)
            self._fault_told = None

    def lost_ticks(self, now_ns: int, count: int) -> None:
        if count <= 0:
            return
        self.lost += count
        if self.warned:
            return
        window = self._window
        window.append((now_ns, count))
        while window and now_ns - window[0][0] > LOST_WINDOW_NS:
            window.pop(0)
        recent = sum(n for _, n in window)
        if recent < LOST_TICKS_WARN:
            return
        self.warned = True
        window.clear()
        if self.realtime:
            log.warning(
                "the haptic loop is losing ticks (%d in the last second) even "
                "with real-time scheduling: another real-time task or the machine "
                "(a VM's stolen time) takes its CPU; each lost tick zeroes the "
                "force. `sasprobe status` counts them; this is said once",
                recent,
            )
        else:
            log.warning(
                "the haptic loop is losing ticks (%d in the last second): it shares the CPU with "
                "every other process, and each lost tick zeroes the force. To fix it, %s. This "
                "is said once; `sasprobe status` counts them",
                recent,
                REALTIME_FIX,
            )

    def stall(self, length_ns: int, zeroed_after_ns: int | None, now_ns: int) -> None:
        if length_ns < STALL_LOG_NS:
            return
        zero = (
            "could not write zero force (a driver call held the device)"
            if zeroed_after_ns is None
            else f"the watchdog zeroed the force {zeroed_after_ns / 1e6:.1f} ms after the last tick"
        )
        self._stalls.say(f"the haptic loop stalled for {length_ns / 1e6:.1f} ms; {zero}", now_ns)


class Reconnector:
    """Calls the device's reconnect() once it has kept failing, at a bounded rate."""

    def __init__(self, device: HapticDevice) -> None:
        self.device = device
        self._failing_since_ns: int | None = None
        self._last_attempt_ns = 0

    def answered(self) -> None:
        """The device gave a state this tick."""
        self._failing_since_ns = None

    def failed(self, now_ns: int) -> bool:
        """The device gave nothing this tick; True when a reconnect() just succeeded."""
        if self._failing_since_ns is None:
            self._failing_since_ns = now_ns
        if (
            now_ns - self._failing_since_ns < RECONNECT_AFTER_NS
            or now_ns - self._last_attempt_ns < RECONNECT_INTERVAL_NS
        ):
            return False
        self._last_attempt_ns = now_ns
        try:
            self.device.reconnect()
        except DeviceFault as exc:
            log.info("device reconnect failed: %s", exc)
            return False
        log.warning("device reconnected")
        return True
