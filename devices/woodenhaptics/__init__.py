"""WoodenHaptics-family arms (Woody, the vintage PHANTOM retrofit, Polhem) on their Teensy firmware.

`models.py` holds every per-model constant, `protocol.py` the line protocol,
`kinematics.py` hfabapi's counts → pose and force → currents, `driver.py` the device.
"""

from sasprobe.devices.woodenhaptics.driver import WoodenHapticsDevice, create

__all__ = ["WoodenHapticsDevice", "create"]
