"""Devices: the interface, drivers of real arms, the simulated and the replay device."""

from sasprobe.devices.base import (
    PHANTOM_OMNI_LIMITS,
    DeviceFault,
    DeviceInfo,
    DeviceLimits,
    DeviceOpenError,
    DeviceState,
    HapticDevice,
)
from sasprobe.devices.registry import open_device

__all__ = [
    "PHANTOM_OMNI_LIMITS",
    "DeviceFault",
    "DeviceInfo",
    "DeviceLimits",
    "DeviceOpenError",
    "DeviceState",
    "HapticDevice",
    "open_device",
]
