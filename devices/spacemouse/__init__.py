"""3Dconnexion SpaceMouse family over HID (hidapi): an input-only 6-DoF device.

`models` holds which products are taken and how each maps (spacenavd's tables),
`protocol` the HID reports, descriptor and axis normalisation, `driver` the device.
"""
