"""Force Dimension arms through the vendor's DHD library.

`dhd` holds the library's constants and signatures (the public header dhdc.h), `models`
the per-model limits (CHAI3D's table), `frame` the one mapping from DHD's frame to
sasprobe's, `driver` the device.
"""

from __future__ import annotations

from sasprobe.devices.base import DeviceOpenError
from sasprobe.devices.forcedimension.driver import ForceDimensionDevice, list_arms

__all__ = ["ForceDimensionDevice", "create", "list_arms"]


def create(argument: str | None = None, **options) -> ForceDimensionDevice:
    """`forcedimension[:INDEX]`: the INDEX-th arm the SDK counts (default 0). Option: library."""
    text = (argument or "").strip()
    try:
        index = int(text) if text else 0
    except ValueError:
        raise DeviceOpenError(f"forcedimension:{text}: expected an arm index (0, 1, ...)") from None
    return ForceDimensionDevice(index, library=options.get("library"))
