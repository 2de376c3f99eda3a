"""3Dconnexion SpaceMouse family over HID (hidapi): an input-only 6-DoF device.

`models` holds which products are taken and how each maps (spacenavd's tables),
`protocol` the HID reports, descriptor and axis normalisation, `driver` the device.
"""

from __future__ import annotations

from sasprobe.devices.hardware import factory_from_environment
from sasprobe.devices.spacemouse.driver import SpaceMouseDevice


def create(argument: str | None = None, **options) -> SpaceMouseDevice:
    """`spacemouse[:PATH]` (PATH as `sasprobe devices` prints it). Options: hid_api, speed_mm_s.

    Without `hid_api`, SASPROBE_HID_API=module:function names a factory of a stand-in for
    the hidapi module (how the test suite points a daemon subprocess at an emulated cap).
    """
    hid_api = options.get("hid_api") or factory_from_environment("SASPROBE_HID_API")
    return SpaceMouseDevice(
        argument or None, hid_api=hid_api, speed_mm_s=float(options.get("speed_mm_s", 100.0))
    )
