"""The scene message: every key is documented in protocol/README.md and validated."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from sasprobe.protocol.scene import (
    SceneError,
    decode_scene,
    encode_scene,
    merge_lights,
)

from tests.support.scene import example_scene

README = Path(__file__).resolve().parent.parent / "protocol" / "README.md"


def _keys(obj, prefix=""):
    for key, value in obj.items():
        yield prefix + key
        if isinstance(value, dict) and key not in ("device",):
            yield from _keys(value, prefix + key + ".")


def test_every_scene_key_is_documented():
    text = README.read_text()
    section = text[text.index("## `scene`") :]
    for key in _keys(example_scene()):
        assert f"`{key}`" in section, f"scene key {key} is not documented in protocol/README.md"


def test_round_trip_and_partial_light_updates():
    scene = example_scene()
    assert decode_scene(encode_scene(scene)) == scene
    lights = merge_lights(scene["lights"], {"probe": {"enabled": False}})
    assert lights["probe"] == {"enabled": False}
    assert lights["directional"] == scene["lights"]["directional"]
    with pytest.raises(SceneError, match="unknown field lights.probe.radius_A"):
        merge_lights(
            scene["lights"], {"probe": {"radius_A": 1.4}}
        )  # the probe's radius is probe_radius_A
    with pytest.raises(SceneError, match="must not be zero"):
        merge_lights(scene["lights"], {"directional": {"direction": [0, 0, 0]}})


def _mutations():
    """(what, change) pairs, each making the example scene break the documented format."""
    yield "no structure", lambda s: s.pop("structure")
    yield "n_atoms text", lambda s: s["structure"].update(n_atoms="327")
    yield "negative radius", lambda s: s.update(probe_radius_A=-1.0)
    yield "cube flag text", lambda s: s["nav_cube"].update(enabled="yes")
    yield "nine planes", lambda s: s.update(clip_planes=[[1.0, 0, 0, 0]] * 9)
    yield "short plane", lambda s: s.update(clip_planes=[[1.0, 0, 0]])
    yield "light direction of 2", lambda s: s["lights"]["directional"].update(direction=[1.0, 0.0])
    yield "probe light missing", lambda s: s["lights"].pop("probe")
    yield "unknown method", lambda s: s["haptics"].update(method="spring")
    yield "unknown colour scheme", lambda s: s.update(color_scheme="rainbow")
    yield "mark without position", lambda s: s["marks"][0].pop("position_A")
    yield "mark label of 81", lambda s: s["marks"][0].update(label="x" * 81)
    yield "version 2", lambda s: s.update(version=2)
    yield "device not an object", lambda s: s.update(device="sim")


@pytest.mark.parametrize("what, change", list(_mutations()), ids=[w for w, _ in _mutations()])
def test_the_decoder_and_the_schema_refuse_the_same_scenes(what, change):
    """The renderer's decoder checks scenes by hand (the schema validator takes tens of ms on
    a scene of 500 marks, too long for a frame); both must refuse what the format forbids."""
    from sasprobe.protocol.schemas import validation_errors

    scene = example_scene()
    assert validation_errors("scene", scene) == []
    change(scene)
    assert validation_errors("scene", scene), f"the schema accepts a scene with {what}"
    with pytest.raises(SceneError):
        decode_scene(json.dumps(scene).encode())
