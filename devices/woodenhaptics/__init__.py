"""WoodenHaptics-family arms (Woody, the vintage PHANTOM retrofit, Polhem) on their Teensy firmware.

`models.py` holds every per-model constant, `protocol.py` the line protocol,
`kinematics.py` hfabapi's counts → pose and force → currents, `driver.py` the device.
"""
