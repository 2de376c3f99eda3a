"""Haply Inverse3 arms through Haply's Inverse Service (its WebSocket simulation channel).

`protocol` holds the 3.x JSON messages and the one mapping from Haply's frame to
sasprobe's, `models` what is assumed of each arm, `driver` the device.
"""

from __future__ import annotations

from sasprobe.devices.inverse3.driver import Inverse3Device, list_arms
from sasprobe.devices.inverse3.models import NOMINAL_RATE_HZ
from sasprobe.devices.inverse3.protocol import DEFAULT_URL
from sasprobe.devices.serial_arm import (
    READ_WAIT_PERIODS,
    REPLY_PERIODS,
)  # the same one-in-flight policy

__all__ = ["Inverse3Device", "create", "list_arms"]


def create(argument: str | None = None, **options) -> Inverse3Device:
    """`inverse3[:URL]` (default ws://localhost:10001). Options: rate_hz (the daemon's loop
    rate, which sets the read wait and the reply timeout; default the arms' nominal rate),
    reply_timeout_s, read_wait_s."""
    url = (argument or "").strip() or DEFAULT_URL
    timing = {
        k: float(options[k])
        for k in ("reply_timeout_s", "read_wait_s")
        if options.get(k) is not None
    }
    rate = float(options.get("rate_hz") or NOMINAL_RATE_HZ)
    timing.setdefault("reply_timeout_s", REPLY_PERIODS / rate)
    timing.setdefault("read_wait_s", READ_WAIT_PERIODS / rate)
    return Inverse3Device(url, **timing)
