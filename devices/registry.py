"""`--device` strings: SCHEME[:ARGUMENT], e.g. `sim`, `sim:scan`, `replay:session.mcap`.

Each scheme names a factory `module:function` imported only when used, so a missing
optional dependency of one driver never breaks the others. A factory takes the
argument after the colon (or None) and keyword options, and returns an unopened
HapticDevice. Schemes whose device lives above devices/ (the daemon's `replay`) are
added by their owner with `register_scheme`, so nothing here imports upward.
"""

from __future__ import annotations

import importlib
from dataclasses import dataclass

from sasprobe.devices.base import DeviceOpenError, HapticDevice


@dataclass(frozen=True)
class DeviceScheme:
    factory: str  # "sasprobe.devices.module:function"
    summary: str  # one line for --help and `sasprobe devices`
    example: str


# Drivers add one line here.
SCHEMES: dict[str, DeviceScheme] = {
    "falcon": DeviceScheme(
        "sasprobe.devices.falcon.driver:create", "Novint Falcon over USB", "falcon:FIRMWARE"
    ),
    "woodenhaptics": DeviceScheme(
        "sasprobe.devices.woodenhaptics.driver:create",
        "WoodenHaptics Woody, vintage PHANTOM retrofit or Polhem (Teensy serial)",
        "woodenhaptics:/dev/ttyACM0",
    ),
    "haply": DeviceScheme(
        "sasprobe.devices.haply.driver:create",
        "Haply 2DIY on an M0/M3 board (gen 3; haply:gen2:PORT)",
        "haply:/dev/ttyACM0",
    ),
    "spacemouse": DeviceScheme(
        "sasprobe.devices.spacemouse.driver:create",
        "3Dconnexion SpaceMouse (input only)",
        "spacemouse",
    ),
    "openhaptics": DeviceScheme(
        "sasprobe.devices.openhaptics.driver:create",
        "PHANTOM Omni/Touch via OpenHaptics",
        "openhaptics",
    ),
    "forcedimension": DeviceScheme(
        "sasprobe.devices.forcedimension.driver:create",
        "Force Dimension omega/sigma/delta/lambda (or a Falcon) via the DHD SDK; INDEX picks "
        "one of several arms",
        "forcedimension:0",
    ),
    "inverse3": DeviceScheme(
        "sasprobe.devices.inverse3.driver:create",
        "Haply Inverse3/Minverse via Haply's Inverse Service (default ws://localhost:10001)",
        "inverse3:ws://localhost:10001",
    ),
    "sim": DeviceScheme(
        "sasprobe.devices.simulated.arm:make_simulated",
        "simulated arm driven by a scripted hand (scan, dive, press, orbit, random, sweep)",
        "sim:scan",
    ),
}


def register_scheme(name: str, scheme: DeviceScheme) -> None:
    """Add a scheme from a layer above devices/ (the daemon registers `replay`)."""
    SCHEMES[name] = scheme


def parse_device_spec(spec: str) -> tuple[str, str | None]:
    scheme, sep, argument = spec.partition(":")
    scheme = scheme.strip().lower()
    return scheme, (argument if sep else None)


def open_device(spec: str, **options: object) -> HapticDevice:
    """Create (not open) the device a --device string names; DeviceOpenError if unknown."""
    scheme, argument = parse_device_spec(spec)
    entry = SCHEMES.get(scheme)
    if entry is None:
        known = ", ".join(sorted(SCHEMES)) or "none"
        raise DeviceOpenError(f"unknown device '{spec}' (known: {known})")
    module_name, _, function = entry.factory.partition(":")
    factory = getattr(importlib.import_module(module_name), function)
    return factory(argument, **options)
