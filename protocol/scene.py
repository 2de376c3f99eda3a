"""The `scene` message: UTF-8 JSON describing everything a renderer draws besides the pose.

Published on topic b"scene" whenever it changes and at least once a second (and at
once when a subscriber joins), and returned by the control command `get_scene`.
The keys are documented in protocol/README.md; `validate_scene` checks them.
"""

from __future__ import annotations

import json
import math

SCENE_TOPIC = b"scene"
# 3: view, color_scheme, marks; 2: nav_cube.half_A and lights.probe.radius_A are gone
SCENE_VERSION = 3
MAX_SCENE_BYTES = 1 << 20  # a scene is a few KiB; anything this big is not one
MAX_CLIP_PLANES = 8
MAX_MARKS = 500  # marks a scene carries (a session's findings, not a point cloud)
MAX_MARK_LABEL = 80  # characters of a mark's label
# the `method` a scene reports and a `set` may ask for; the first is the default
HAPTIC_METHODS = ("proxy", "penalty")
# How renderers colour the atoms (molecule/colors.py says what each means); the optional scene
# key `color_scheme` is one of these, or null for the renderer's default by structure.
COLOR_SCHEMES = (
    "element",
    "chain",
    "chain-all",
    "polymer",
    "residue",
    "hydrophobicity",
    "bfactor",
    "sas",
)

# The direction the key light travels (from the light towards the molecule), molecule frame,
# not normalised: from the upper left front of a view down -z (the renderer's fitted view).
# The daemon publishes it and the standalone renderer starts with it.
DEFAULT_LIGHT_DIRECTION = (0.45, -0.55, -0.70)

DEFAULT_LIGHTS = {
    "directional": {"direction": list(DEFAULT_LIGHT_DIRECTION)},
    "probe": {"enabled": True},  # a point light at the probe centre
}


class SceneError(ValueError):
    """A scene (or part of one) that breaks the documented schema; the message is one line."""


def _number(value, where: str, positive: bool = False) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise SceneError(f"{where} must be a number, not {type(value).__name__}")
    value = float(value)
    if not math.isfinite(value):
        raise SceneError(f"{where} must be finite")
    if positive and value <= 0:
        raise SceneError(f"{where} must be positive")
    return value


def _vector(value, n: int, where: str) -> list[float]:
    if not isinstance(value, (list, tuple)) or len(value) != n:
        raise SceneError(f"{where} must be a list of {n} numbers")
    return [_number(x, f"{where}[{i}]") for i, x in enumerate(value)]


def _object(value, where: str) -> dict:
    if not isinstance(value, dict):
        raise SceneError(f"{where} must be an object, not {type(value).__name__}")
    return value


def _bool(value, where: str) -> bool:
    if not isinstance(value, bool):
        raise SceneError(f"{where} must be true or false")
    return value


def validate_clip_planes(value) -> list[list[float]]:
    """[[a, b, c, d], ...]: a·x + b·y + c·z + d ≥ 0 (x, y, z in Å) is the side that is kept."""
    if not isinstance(value, (list, tuple)):
        raise SceneError("clip_planes must be a list of [a, b, c, d]")
    if len(value) > MAX_CLIP_PLANES:
        raise SceneError(f"at most {MAX_CLIP_PLANES} clip planes, got {len(value)}")
    planes = []
    for i, plane in enumerate(value):
        p = _vector(plane, 4, f"clip_planes[{i}]")
        if p[0] == p[1] == p[2] == 0.0:
            raise SceneError(f"clip_planes[{i}] has a zero normal (a, b, c)")
        planes.append(p)
    return planes


def validate_color_scheme(value) -> str | None:
    """A colour scheme name, or None (each renderer picks its default by structure)."""
    if value is not None and value not in COLOR_SCHEMES:
        raise SceneError(
            f"color_scheme must be one of {', '.join(COLOR_SCHEMES)} or null, got "
            f"{str(value)[:40]!r}"
        )
    return value


def validate_mark_label(value) -> str:
    """A mark's label: a string of at most MAX_MARK_LABEL printable characters."""
    if not isinstance(value, str):
        raise SceneError("a mark label must be a string")
    if len(value) > MAX_MARK_LABEL or not value.isprintable():
        raise SceneError(f"a mark label is at most {MAX_MARK_LABEL} printable characters")
    return value


def validate_marks(value) -> list:
    """The scene's `marks`: [{"id", "label", "position_A", "seq", "source"}, ...] in id order."""
    if not isinstance(value, list):
        raise SceneError("marks must be a list")
    if len(value) > MAX_MARKS:
        raise SceneError(f"at most {MAX_MARKS} marks, got {len(value)}")
    for i, mark in enumerate(value):
        mark = _object(mark, f"marks[{i}]")
        for key in ("id", "seq"):
            if (
                isinstance(mark.get(key), bool)
                or not isinstance(mark.get(key), int)
                or mark[key] < 0
            ):
                raise SceneError(f"marks[{i}].{key} must be a non-negative integer")
        validate_mark_label(mark.get("label"))
        _vector(mark.get("position_A"), 3, f"marks[{i}].position_A")
        if not isinstance(mark.get("source"), str):
            raise SceneError(f"marks[{i}].source must be a string")
    return value


def merge_lights(current: dict, changes) -> dict:
    """Apply a (possibly partial) lights object to the current one, validating every value."""
    changes = _object(changes, "lights")
    merged = json.loads(json.dumps(current))
    for name, fields in changes.items():
        if name not in DEFAULT_LIGHTS:
            raise SceneError(f"unknown light '{name}' (known: {', '.join(DEFAULT_LIGHTS)})")
        for key, value in _object(fields, f"lights.{name}").items():
            if key not in DEFAULT_LIGHTS[name]:
                raise SceneError(f"unknown field lights.{name}.{key}")
            merged[name][key] = value
    _check_lights(merged)
    return merged


def _check_lights(lights) -> None:
    lights = _object(lights, "lights")
    for name in DEFAULT_LIGHTS:
        _object(lights.get(name), f"lights.{name}")
    direction = _vector(lights["directional"].get("direction"), 3, "lights.directional.direction")
    if direction == [0.0, 0.0, 0.0]:
        raise SceneError("lights.directional.direction must not be zero")
    _bool(lights["probe"].get("enabled"), "lights.probe.enabled")


def validate_scene(scene) -> dict:
    """Check the keys a renderer relies on; unknown extra keys are allowed (newer daemons)."""
    scene = _object(scene, "scene")
    version = scene.get("version")
    if isinstance(version, bool) or not isinstance(version, int) or version < SCENE_VERSION:
        raise SceneError(f"scene version must be an integer ≥ {SCENE_VERSION}")
    structure = _object(scene.get("structure"), "structure")
    if not isinstance(structure.get("name"), str) or not isinstance(structure.get("sha256"), str):
        raise SceneError("structure.name and structure.sha256 must be strings")
    n_atoms = structure.get("n_atoms")
    if isinstance(n_atoms, bool) or not isinstance(n_atoms, int) or n_atoms < 0:
        raise SceneError("structure.n_atoms must be a non-negative integer")
    _number(scene.get("probe_radius_A"), "probe_radius_A", positive=True)
    cube = _object(scene.get("nav_cube"), "nav_cube")
    _bool(cube.get("enabled"), "nav_cube.enabled")
    validate_clip_planes(scene.get("clip_planes"))
    _check_lights(scene.get("lights"))
    _object(scene.get("device"), "device")
    haptics = _object(scene.get("haptics"), "haptics")
    if haptics.get("method") not in HAPTIC_METHODS:
        raise SceneError(f"haptics.method must be one of {', '.join(HAPTIC_METHODS)}")
    _number(haptics.get("stiffness_n_per_mm"), "haptics.stiffness_n_per_mm")
    _number(haptics.get("damping_n_s_per_m"), "haptics.damping_n_s_per_m")
    validate_color_scheme(scene.get("color_scheme"))  # optional: absent reads as null
    if not isinstance(scene.get("daemon_version"), str):
        raise SceneError("daemon_version must be a string")
    if "marks" in scene:  # optional: daemons before marks do not send it
        validate_marks(scene["marks"])
    return scene


def reject_constant(name: str):
    """json.loads hook: NaN and Infinity are not JSON."""
    raise ValueError(f"{name} is not a JSON number")


def encode_scene(scene: dict) -> bytes:
    return json.dumps(validate_scene(scene), separators=(",", ":"), allow_nan=False).encode()


def decode_scene(payload: bytes) -> dict:
    if len(payload) > MAX_SCENE_BYTES:
        raise SceneError(f"scene of {len(payload)} bytes is larger than {MAX_SCENE_BYTES}")
    try:
        scene = json.loads(payload.decode("utf-8"), parse_constant=reject_constant)
    except (UnicodeDecodeError, ValueError) as exc:
        raise SceneError(f"scene is not UTF-8 JSON ({exc})") from None
    return validate_scene(scene)
