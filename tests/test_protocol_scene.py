"""The scene message: every key is documented in protocol/README.md and validated."""

from __future__ import annotations

from pathlib import Path

import pytest

from sasprobe.devices.base import PHANTOM_OMNI_LIMITS, DeviceInfo
from sasprobe.protocol.scene import DEFAULT_LIGHTS, SceneError, decode_scene, encode_scene, merge_lights

README = Path(__file__).resolve().parent.parent / "protocol" / "README.md"


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
        "marks": [{"id": 1, "label": "mark 1", "position_A": [1.0, 2.0, 3.0], "seq": 1200, "source": "button"}],
    }


def _keys(obj, prefix=""):
    for key, value in obj.items():
        yield prefix + key
        if isinstance(value, dict) and key not in ("device",):
            yield from _keys(value, prefix + key + ".")


def test_every_scene_key_is_documented():
    text = README.read_text()
    section = text[text.index("## `scene`"):]
    for key in _keys(example_scene()):
        assert f"`{key}`" in section, f"scene key {key} is not documented in protocol/README.md"


def test_round_trip_and_partial_light_updates():
    scene = example_scene()
    assert decode_scene(encode_scene(scene)) == scene
    lights = merge_lights(scene["lights"], {"probe": {"enabled": False}})
    assert lights["probe"] == {"enabled": False}
    assert lights["directional"] == scene["lights"]["directional"]
    with pytest.raises(SceneError, match="unknown field lights.probe.radius_A"):
        merge_lights(scene["lights"], {"probe": {"radius_A": 1.4}})  # the probe's radius is probe_radius_A
    with pytest.raises(SceneError, match="must not be zero"):
        merge_lights(scene["lights"], {"directional": {"direction": [0, 0, 0]}})
