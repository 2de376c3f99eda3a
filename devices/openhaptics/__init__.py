"""PHANTOM Omni / Touch and other HDAPI arms through the vendor's OpenHaptics HD library.

`hdapi` holds the library's constants, signatures and error classes (the public
headers), `driver` the device (the SDK examples' calibration and error handling).
"""

from __future__ import annotations

from sasprobe.devices.openhaptics.driver import RESET_ENCODERS, OpenHapticsDevice


def create(argument: str | None = None, **options) -> OpenHapticsDevice:
    """`openhaptics[:NAME][:reset-encoders]` (NAME as configured, e.g. "Default PHANToM").

    `reset-encoders` says the arm is held at its reset position now (for arms calibrated
    by an encoder reset). Options: library, read_timeout_s.
    """
    name, reset = argument or "", False
    head, sep, tail = name.rpartition(":")
    if tail == RESET_ENCODERS:
        name, reset = (head if sep else ""), True
    return OpenHapticsDevice(
        name or None,
        library=options.get("library"),
        reset_encoders=reset,
        read_timeout_s=float(options.get("read_timeout_s", 0.05)),
    )
