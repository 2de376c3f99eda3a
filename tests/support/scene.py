"""A scene message with every key the protocol documents, for the protocol's tests."""

from __future__ import annotations

from sasprobe.devices.base import PHANTOM_OMNI_LIMITS, DeviceInfo
from sasprobe.protocol.scene import DEFAULT_LIGHTS, merge_lights


def example_scene() -> dict:
    return {
        "version": 3,
        "revision": 3,
        "daemon_version": "0.1.0",
        "structure": {"name": "1crn", "sha256": "ab" * 32, "n_atoms": 327},
        "probe_radius_A": 1.4,
        "nav_cube": {"enabled": True},
        "clip_planes": [[1.0, 0.0, 0.0, -3.0]],
        "lights": merge_lights(DEFAULT_LIGHTS, {}),
        "device": DeviceInfo("sim", "simulated arm", PHANTOM_OMNI_LIMITS).as_dict(),
        "haptics": {"method": "proxy", "stiffness_n_per_mm": 0.3, "damping_n_s_per_m": 0.2},
        "rate_hz": 1000.0,
        "view": {"rotation": [[0.0, 0.0, 1.0], [0.0, 1.0, 0.0], [-1.0, 0.0, 0.0]]},
        "color_scheme": "chain",
        "marks": [
            {
                "id": 1,
                "label": "mark 1",
                "position_A": [1.0, 2.0, 3.0],
                "seq": 1200,
                "source": "button",
            }
        ],
    }
