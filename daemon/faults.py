"""The loop's fault bookkeeping: a log that does not flood, and when to try reconnect().

A device that fails for RECONNECT_AFTER_NS (a blip does not count) gets `reconnect()`
every RECONNECT_INTERVAL_NS until it answers again. Both run on the loop thread and take
the tick's time as an argument.
"""

from __future__ import annotations

import logging

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
        if now_ns - self._failing_since_ns < RECONNECT_AFTER_NS or now_ns - self._last_attempt_ns < RECONNECT_INTERVAL_NS:
            return False
        self._last_attempt_ns = now_ns
        try:
            self.device.reconnect()
        except DeviceFault as exc:
            log.info("device reconnect failed: %s", exc)
            return False
        log.warning("device reconnected")
        return True
